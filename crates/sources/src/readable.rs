//! Sizes as a person reads them in a message, and the memory a run may
//! still take, checked before it is taken.

use crate::error::{Error, Result};

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

/// The memory this process may still take, in bytes: the machine's
/// available memory (Linux's `MemAvailable`), or less where the process's
/// address space is limited (`ulimit -v`, less what it has mapped);
/// `None` where neither is known (another system).
pub fn available_memory() -> Option<u64> {
    let field = |text: &str, key: &str| -> Option<u64> {
        let line = text.lines().find(|l| l.starts_with(key))?;
        line[key.len()..].split_whitespace().next()?.parse().ok()
    };
    let machine = std::fs::read_to_string("/proc/meminfo")
        .ok()
        .and_then(|text| field(&text, "MemAvailable:"))
        .map(|kb| kb.saturating_mul(1024));
    let limited = std::fs::read_to_string("/proc/self/limits")
        .ok()
        .and_then(|text| field(&text, "Max address space"))
        .and_then(|limit| {
            let status = std::fs::read_to_string("/proc/self/status").ok()?;
            let mapped = field(&status, "VmSize:")?.saturating_mul(1024);
            Some(limit.saturating_sub(mapped))
        });
    match (machine, limited) {
        (Some(a), Some(b)) => Some(a.min(b)),
        (a, b) => a.or(b),
    }
}

/// Refuses `count` items of `each` bytes (`what` they are, for the
/// message) where they would not fit in [`available_memory`], before any
/// is allocated: a setting (`name` = `count`) a typo of a few zeros makes
/// too large would otherwise end the process when the allocation fails.
///
/// ```
/// use twostage_sources::{available_memory, refuse_beyond_memory};
/// assert!(refuse_beyond_memory("simulations", 1000, 80, "records").is_ok());
/// // Where the system says what it has (Linux).
/// if available_memory().is_some() {
///     let refused = refuse_beyond_memory("simulations", usize::MAX, 80, "records").unwrap_err();
///     assert!(refused.to_string().starts_with("invalid simulations = 18446744073709551615: \
///         its records take 1475.7 EB"), "{refused}");
/// }
/// ```
///
/// # Errors
/// [`Error::InvalidSetting`] naming `name`, the memory the items would take
/// and the most that fit.
pub fn refuse_beyond_memory(name: &'static str, count: usize, each: u64, what: &str) -> Result<()> {
    // In f64: a hostile count overflows u64 bytes.
    let total = count as f64 * each as f64;
    let Some(available) = available_memory() else {
        return Ok(());
    };
    if total <= available as f64 {
        return Ok(());
    }
    Err(Error::InvalidSetting {
        name,
        value: count.to_string(),
        reason: format!(
            "its {what} take {} ({} each) before any work, where this process has {} \
             available: at most {} fit",
            readable_bytes(total),
            readable_bytes(each as f64),
            readable_bytes(available as f64),
            available / each.max(1)
        ),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// On Linux the memory a run may take is known, and no more than the
    /// machine's whole memory (read here from its own line).
    #[test]
    #[cfg(target_os = "linux")]
    fn the_available_memory_lies_within_the_machines() {
        let meminfo = std::fs::read_to_string("/proc/meminfo").unwrap();
        let total_kb: u64 = meminfo
            .lines()
            .find_map(|l| l.strip_prefix("MemTotal:"))
            .and_then(|rest| rest.trim().trim_end_matches("kB").trim().parse().ok())
            .unwrap();
        let available = available_memory().unwrap();
        assert!(available > 0 && available <= total_kb * 1024, "{available}");
    }
}
