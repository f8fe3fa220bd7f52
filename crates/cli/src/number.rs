//! Numbers as text: printed so they read back to the same f64, parsed with
//! messages that say which value was wrong.

pub use twostage::sources::csv_rows::format_f64;

/// `v` to four significant digits, for people: plain decimals from 1e-3
/// to 1e5, scientific notation outside (a residual of 1.8e-6 m must not
/// print as 0.0000).
pub fn four_digits(v: f64) -> String {
    let magnitude = v.abs();
    if v == 0.0 || !v.is_finite() {
        format!("{v}")
    } else if (1e-3..1e5).contains(&magnitude) {
        let decimals = (3 - magnitude.log10().floor() as i32).max(0) as usize;
        format!("{v:.decimals$}")
    } else {
        format!("{v:.3e}")
    }
}

/// Parse a comma-separated list of numbers, e.g. `-35,-1.1`.
pub fn parse_list(text: &str, what: &str) -> Result<Vec<f64>, String> {
    text.split(',')
        .enumerate()
        .map(|(i, item)| {
            let item = item.trim();
            item.parse::<f64>()
                .ok()
                .filter(|v| v.is_finite())
                .ok_or_else(|| format!("{what}: value {} ('{item}') is not a finite number", i + 1))
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn four_digits_keep_small_values_readable() {
        assert_eq!(four_digits(1.8e-6), "1.800e-6");
        assert_eq!(four_digits(0.26281), "0.2628");
        assert_eq!(four_digits(-12.3456), "-12.35");
        assert_eq!(four_digits(0.0012345), "0.001234");
        assert_eq!(four_digits(123456.0), "1.235e5");
        assert_eq!(four_digits(0.0), "0");
    }

    #[test]
    fn lists_parse_with_negative_values_and_name_the_bad_item() {
        assert_eq!(parse_list("-35,-1.1", "theta").unwrap(), vec![-35.0, -1.1]);
        assert_eq!(parse_list(" 0.3 ", "theta").unwrap(), vec![0.3]);
        let err = parse_list("1,abc", "--theta").unwrap_err();
        assert!(err.contains("value 2 ('abc')"), "{err}");
        assert!(parse_list("nan", "x").is_err());
        assert!(parse_list("", "x").is_err());
    }
}
