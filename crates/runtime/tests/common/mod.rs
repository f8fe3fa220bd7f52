//! What the runtime's test files share.

use twostage_runtime::format::{CHECKSUM_FROM, HEADER_BYTES};

/// Set the length and checksum of a blob to its bytes, so that a changed
/// blob reaches the checks behind the checksum.
pub fn seal(blob: &mut [u8]) {
    if blob.len() < HEADER_BYTES {
        return;
    }
    let Ok(length) = u32::try_from(blob.len()) else {
        return;
    };
    blob[8..12].copy_from_slice(&length.to_le_bytes());
    let crc = twostage_runtime::format::checksum(&blob[CHECKSUM_FROM..]);
    blob[12..16].copy_from_slice(&crc.to_le_bytes());
}
