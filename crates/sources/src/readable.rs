//! A count a setting makes too large for the memory, refused before it is
//! taken.

use crate::InvalidSetting;
use twostage_models::{available_memory, readable_bytes};

use crate::error::{Error, Result};

/// Refuses `count` items of `each` bytes (`what` they are, for the
/// message) where they would not fit in [`available_memory`], before any
/// is allocated: a setting (`name` = `count`) a typo of a few zeros makes
/// too large would otherwise end the process when the allocation fails.
/// Where they fit, what they take, said for the person watching.
///
/// ```
/// use twostage_sources::{available_memory, refuse_beyond_memory};
/// let said = refuse_beyond_memory("simulations", 1000, 80, "records")?;
/// assert!(said.starts_with("1000 records take 80.0 kB (80 bytes each)"), "{said}");
/// // Where the system says what it has (Linux).
/// if available_memory().is_some() {
///     let refused = refuse_beyond_memory("simulations", usize::MAX, 80, "records").unwrap_err();
///     assert!(refused.to_string().starts_with("invalid simulations = 18446744073709551615: \
///         its records take 1475.7 EB"), "{refused}");
/// }
/// # Ok::<(), twostage_sources::Error>(())
/// ```
///
/// # Errors
/// [`Error::InvalidSetting`] naming `name`, the memory the items would take
/// and the most that fit.
pub fn refuse_beyond_memory(
    name: &'static str,
    count: usize,
    each: u64,
    what: &str,
) -> Result<String> {
    // In f64: a hostile count overflows u64 bytes.
    let total = count as f64 * each as f64;
    let taken = format!(
        "{count} {what} take {} ({} each)",
        readable_bytes(total),
        readable_bytes(each as f64)
    );
    let Some(available) = available_memory() else {
        return Ok(taken);
    };
    if total <= available as f64 {
        return Ok(format!(
            "{taken}, of {} this process may take",
            readable_bytes(available as f64)
        ));
    }
    Err(Error::InvalidSetting(InvalidSetting {
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
    }))
}
