//! What a run may take of the machine, and sizes as a person reads them:
//! the memory a process may still take and the room on a disk, measured
//! before a size that came from outside is allocated or written.

use std::path::Path;

/// A byte count as people read it, in decimal units: "8.0 TB", "1.1 GB".
///
/// ```
/// use twostage_models::readable_bytes;
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

/// The bytes an unprivileged writer may still put on the file system
/// holding `path` (or its nearest existing ancestor, the working folder
/// for a relative path none of whose folders exist); `None` where the
/// system does not say.
///
/// ```
/// let room = twostage_models::free_disk(&std::env::temp_dir());
/// assert!(room.is_none_or(|bytes| bytes < u64::MAX));
/// ```
pub fn free_disk(path: &Path) -> Option<u64> {
    let existing = path
        .ancestors()
        .find(|d| d.exists())
        .unwrap_or(Path::new("."));
    let disk = rustix::fs::statvfs(existing).ok()?;
    Some(disk.f_bavail.saturating_mul(disk.f_frsize))
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

    /// The room of a folder not yet made is its nearest existing
    /// ancestor's, and no more than its disk holds.
    #[test]
    #[cfg(target_os = "linux")]
    fn the_free_disk_is_the_nearest_existing_folders() {
        let temp = std::env::temp_dir();
        let room = free_disk(&temp).unwrap();
        let disk = rustix::fs::statvfs(&temp).unwrap();
        assert!(room <= disk.f_blocks * disk.f_frsize, "{room}");
        let later = free_disk(&temp.join("not/yet/made")).unwrap();
        // Other writers move the free space between the two calls a little.
        assert!(
            later.abs_diff(room) < room / 100 + (1 << 20),
            "{later} {room}"
        );
    }
}
