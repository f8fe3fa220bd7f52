//! Sizes as a person reads them in a message.

/// A byte count as people read it, in decimal units: "8.0 TB", "1.1 GB".
///
/// ```
/// use twostage_sources::readable_bytes;
/// assert_eq!(readable_bytes(512.0), "512 bytes");
/// assert_eq!(readable_bytes(6.3e19), "63.0 EB");
/// ```
pub fn readable_bytes(bytes: f64) -> String {
    let units = ["bytes", "kB", "MB", "GB", "TB", "PB", "EB"];
    let mut value = bytes;
    let mut unit = 0;
    while value >= 1000.0 && unit + 1 < units.len() {
        value /= 1000.0;
        unit += 1;
    }
    if unit == 0 {
        format!("{value} bytes")
    } else {
        format!("{value:.1} {}", units[unit])
    }
}
