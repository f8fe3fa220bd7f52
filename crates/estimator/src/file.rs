//! The estimator file: a small versioned binary container around the
//! postcard encoding of [`Estimator`], and a JSON export for people.
//!
//! Layout (all integers little-endian):
//!
//! | bytes | content |
//! |---|---|
//! | 0..8 | magic `TWOSTAGE` |
//! | 8..12 | format version (u32): 10 for an estimator of a model with parameters held at values, else 9 for one with a conditional density of its parameters, else 8 for one whose stage 1 linearizes the model, 7 for one whose stage 1 learns, else 6 (1 to 5 are still read) |
//! | 12..20 | payload length in bytes (u64) |
//! | 20..24 | CRC-32 (IEEE 802.3) of the payload (u32) |
//! | 24.. | payload: postcard-encoded estimator |

use std::path::Path;

use crate::error::{Error, FileError, Result};
use crate::estimator::Estimator;
use crate::layout::{EstimatorFields, V1, V2, V3, V5, V6, V9, ValidationReportV3};
use twostage_validate::ValidationReport;

/// The first eight bytes of every estimator file.
pub const MAGIC: &[u8; 8] = b"TWOSTAGE";
/// The format version this build writes, and the newest it reads.
///
/// Version 2 added the feature envelope and the adaptive intervals, version
/// 3 the parameters' priors, version 4 the betting certificate of the
/// validation report, version 5 the family of inputs the held-out records
/// spanned, version 6 the density of their input shapes, version 7 a stage
/// 1 that learns (`+learned`); older files load without them
/// (uniform priors, no certificate, no input family, no shapes). Version 7
/// shares version 6's layout and is written only where it is needed, so
/// that a build that reads 6 still reads every estimator without a
/// learned stage 1. Version 8, likewise, a stage 1 that linearizes the
/// model (`linearized`), written only for such an estimator; version 9
/// adds the parameters' conditional density (the posterior's draws),
/// written only for an estimator that has one; version 10 the parameters
/// held at values (`--fix`), written only for an estimator of such a
/// model. Every version's layout
/// lives in `layout.rs`.
pub const FORMAT_VERSION: u32 = 10;
/// The version of an estimator file with a conditional density.
const WITH_POSTERIOR: u32 = 9;
/// The version of an estimator file whose stage 1 linearizes the model.
const WITH_LINEARIZED: u32 = 8;
/// The version of an estimator file whose stage 1 learns.
const WITH_LEARNED: u32 = 7;
/// The version of an estimator file whose stage 1 neither learns nor
/// linearizes.
const WITHOUT_LEARNED: u32 = 6;
const HEADER: usize = 24;

impl Estimator {
    /// Encode the estimator as the bytes of an estimator file.
    ///
    /// # Errors
    /// [`Error::File`] if encoding fails (it does not for valid estimators).
    pub fn to_bytes(&self) -> Result<Vec<u8>> {
        let payload = postcard::to_allocvec(self).map_err(|e| FileError::Encoding {
            reason: e.to_string(),
        })?;
        let mut bytes = Vec::with_capacity(HEADER + payload.len());
        bytes.extend_from_slice(MAGIC);
        let version = if !self.fixed.is_empty() {
            FORMAT_VERSION
        } else if self.posterior.is_some() {
            WITH_POSTERIOR
        } else if self.compressor().linearizes() {
            WITH_LINEARIZED
        } else if self.compressor().learns() {
            WITH_LEARNED
        } else {
            WITHOUT_LEARNED
        };
        bytes.extend_from_slice(&version.to_le_bytes());
        bytes.extend_from_slice(&(payload.len() as u64).to_le_bytes());
        bytes.extend_from_slice(&crc32fast::hash(&payload).to_le_bytes());
        bytes.extend_from_slice(&payload);
        Ok(bytes)
    }

    /// Decode an estimator from the bytes of an estimator file.
    ///
    /// ```
    /// # use twostage::{Estimator, TwoStage};
    /// # use twostage::models::Benchmark;
    /// # let model = Benchmark::builder().n_samples(200).build()?;
    /// # let estimator = TwoStage::builder(&model).simulations(100).validation(0).calibration(0).linear(1e-6)?.train()?;
    /// let bytes = estimator.to_bytes()?;
    /// assert_eq!(Estimator::from_bytes(&bytes)?, estimator);
    /// assert!(Estimator::from_bytes(&bytes[..bytes.len() - 1]).is_err());
    /// # Ok::<(), twostage::Error>(())
    /// ```
    ///
    /// # Errors
    /// [`Error::File`] with the [`FileError`] that says what is wrong: not an
    /// estimator file, written by a newer version, truncated, or corrupted.
    pub fn from_bytes(bytes: &[u8]) -> Result<Self> {
        if bytes.len() < MAGIC.len() || &bytes[..MAGIC.len()] != MAGIC {
            return Err(FileError::BadMagic.into());
        }
        if bytes.len() < HEADER {
            return Err(FileError::Truncated {
                part: "header",
                expected: HEADER as u64,
                found: bytes.len() as u64,
            }
            .into());
        }
        let word = |range: std::ops::Range<usize>| -> [u8; 8] {
            let mut w = [0u8; 8];
            w[..range.len()].copy_from_slice(&bytes[range]);
            w
        };
        let version = u32::from_le_bytes([bytes[8], bytes[9], bytes[10], bytes[11]]);
        if version > FORMAT_VERSION {
            return Err(FileError::NewerVersion {
                found: version,
                supported: FORMAT_VERSION,
            }
            .into());
        }
        if version == 0 {
            return Err(FileError::UnknownVersion { found: version }.into());
        }
        let length = u64::from_le_bytes(word(12..20));
        let checksum = u32::from_le_bytes([bytes[20], bytes[21], bytes[22], bytes[23]]);
        let present = (bytes.len() - HEADER) as u64;
        if length > present {
            return Err(FileError::Truncated {
                part: "payload",
                expected: length,
                found: present,
            }
            .into());
        }
        if length < present {
            return Err(FileError::TrailingBytes {
                extra: present - length,
            }
            .into());
        }
        let payload = &bytes[HEADER..];
        let actual = crc32fast::hash(payload);
        if actual != checksum {
            return Err(FileError::BadChecksum {
                stored: checksum,
                actual,
            }
            .into());
        }
        // Each version's layout, carried forward to today's.
        // A layout must take the whole payload: bytes left over are another
        // version's fields, not this one's.
        fn read<'a, F: serde::Deserialize<'a>>(
            payload: &'a [u8],
        ) -> std::result::Result<F, String> {
            let (fields, rest) =
                postcard::take_from_bytes::<F>(payload).map_err(|e| e.to_string())?;
            if rest.is_empty() {
                Ok(fields)
            } else {
                Err(format!(
                    "{} bytes follow the fields of this format version (a file of another \
                     version under this header?)",
                    rest.len()
                ))
            }
        }
        let fields: std::result::Result<EstimatorFields, String> = match version {
            1 => read::<V1<ValidationReportV3>>(payload)
                .map(|v1| V5::from(V3::<ValidationReport>::from(V3::from(V2::from(v1)))).into()),
            2 => read::<V2<ValidationReportV3>>(payload)
                .map(|v2| V5::from(V3::<ValidationReport>::from(V3::from(v2))).into()),
            3 => read::<V3<ValidationReportV3>>(payload)
                .map(|v3| V5::from(V3::<ValidationReport>::from(v3)).into()),
            4 => read::<V3<ValidationReport>>(payload).map(|v4| V5::from(v4).into()),
            5 => read::<V5>(payload).map(Into::into),
            6..=8 => read::<V6>(payload).map(Into::into),
            9 => read::<V9>(payload).map(Into::into),
            _ => read::<EstimatorFields>(payload),
        };
        fields
            .and_then(|fields| Estimator::try_from(fields).map_err(|e| e.to_string()))
            .map_err(|reason| FileError::Undecodable { reason }.into())
    }

    /// Write the estimator file to `path`, whole or not at all
    /// ([`write_whole`]): a kill or a full disk mid-write leaves the file
    /// that was there.
    ///
    /// # Errors
    /// [`Error::Io`] if the file cannot be written.
    pub fn save(&self, path: impl AsRef<Path>) -> Result<()> {
        write_whole(path, &self.to_bytes()?)
    }

    /// Read an estimator file.
    ///
    /// # Errors
    /// [`Error::Io`] if it cannot be read, [`Error::File`] as in
    /// [`Estimator::from_bytes`] (the message names the file).
    pub fn load(path: impl AsRef<Path>) -> Result<Self> {
        let path = path.as_ref();
        let io = |cause| Error::Io {
            path: path.display().to_string(),
            cause,
        };
        let size = std::fs::metadata(path).map_err(io)?.len();
        if let Some(available) = twostage_models::available_memory()
            && size > available
        {
            return Err(io(std::io::Error::other(format!(
                "a file of {}, where this process has {} available: not an estimator file \
                 (those take kilobytes to a few megabytes)",
                twostage_models::readable_bytes(size as f64),
                twostage_models::readable_bytes(available as f64)
            ))));
        }
        let bytes = std::fs::read(path).map_err(io)?;
        Self::from_bytes(&bytes).map_err(|e| match e {
            Error::File { error, .. } => Error::File {
                path: Some(path.to_path_buf()),
                error,
            },
            other => other,
        })
    }

    /// The whole estimator as pretty JSON, for people and other tools
    /// (infinite interval widths become `null`).
    ///
    /// # Errors
    /// [`Error::File`] if serialization fails.
    pub fn to_json(&self) -> Result<String> {
        serde_json::to_string_pretty(self).map_err(|e| {
            FileError::Encoding {
                reason: format!("JSON: {e}"),
            }
            .into()
        })
    }
}

/// Write `bytes` to `path` whole or not at all: to a temporary file beside
/// it, flushed to disk, then renamed over `path`, so that a kill or a full
/// disk during the write leaves whatever was at `path` before (an
/// estimator it replaces, say) instead of a file cut short.
///
/// A path that is not a regular file (`/dev/null`, a FIFO, a terminal) is
/// written through, never replaced: renaming over `/dev/null` as root
/// would turn the device into a file that every later reader of
/// `/dev/null` sees. A symbolic link keeps pointing where it did; the file
/// it names is replaced.
///
/// ```
/// let path = std::env::temp_dir().join(format!("whole-{}.txt", std::process::id()));
/// twostage::write_whole(&path, b"one")?;
/// twostage::write_whole(&path, b"two")?;
/// assert_eq!(std::fs::read(&path)?, b"two");
/// # std::fs::remove_file(&path)?;
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
///
/// # Errors
/// [`Error::Io`] naming `path` when the folder cannot take the file.
pub fn write_whole(path: impl AsRef<Path>, bytes: &[u8]) -> Result<()> {
    use std::io::Write;
    let path = path.as_ref();
    let io = |cause: std::io::Error| Error::Io {
        path: path.display().to_string(),
        cause,
    };
    let (target, dir) = match destination(path).map_err(io)? {
        Destination::Through => return std::fs::write(path, bytes).map_err(io),
        Destination::Replace { target, dir } => (target, dir),
    };
    let mut file = temporary_in(&dir).map_err(io)?;
    // The file replaced keeps its mode, as `std::fs::write` keeps it.
    if let Ok(existing) = std::fs::metadata(&target) {
        file.as_file()
            .set_permissions(existing.permissions())
            .map_err(io)?;
    }
    file.write_all(bytes).map_err(io)?;
    file.as_file().sync_all().map_err(io)?;
    file.persist(&target).map_err(|e| io(e.error))?;
    Ok(())
}

/// Whether [`write_whole`] could write `path`, tried before the work that
/// makes its bytes (a training of minutes that ends unable to save is
/// lost): a temporary file is made beside it and removed.
///
/// ```
/// assert!(twostage::check_writable(std::env::temp_dir().join("x.tsest")).is_ok());
/// let refused = twostage::check_writable("/no/such/folder/x.tsest").unwrap_err();
/// assert!(refused.to_string().contains("/no/such/folder/x.tsest"), "{refused}");
/// ```
///
/// # Errors
/// [`Error::Io`] naming `path` and what the system said.
pub fn check_writable(path: impl AsRef<Path>) -> Result<()> {
    let path = path.as_ref();
    let io = |cause: std::io::Error| Error::Io {
        path: path.display().to_string(),
        cause,
    };
    match destination(path).map_err(io)? {
        Destination::Through => std::fs::OpenOptions::new()
            .write(true)
            .open(path)
            .map(drop)
            .map_err(io),
        Destination::Replace { dir, .. } => temporary_in(&dir).map(drop).map_err(io),
    }
}

/// Where [`write_whole`] puts a file.
enum Destination {
    /// Not a regular file (a device, a FIFO): written through.
    Through,
    /// Written beside `target` in `dir`, then renamed over it.
    Replace {
        target: std::path::PathBuf,
        dir: std::path::PathBuf,
    },
}

fn destination(path: &Path) -> std::io::Result<Destination> {
    let target = match std::fs::metadata(path) {
        Ok(existing) if !existing.is_file() => return Ok(Destination::Through),
        Ok(_) => std::fs::canonicalize(path)?,
        Err(_) => path.to_path_buf(),
    };
    let dir = match target.parent() {
        Some(parent) if !parent.as_os_str().is_empty() => parent.to_path_buf(),
        _ => Path::new(".").to_path_buf(),
    };
    Ok(Destination::Replace { target, dir })
}

/// A temporary file in `dir`; the system's words for a failure, without
/// the temporary name that the user never gave.
/// A temporary file in `dir` made with the mode a new file of
/// `std::fs::write` gets (read and write for all, less the umask), not
/// the owner-only mode of a temporary file: the estimator file it
/// becomes is shared as any other output.
fn temporary_in(dir: &Path) -> std::io::Result<tempfile::NamedTempFile> {
    let mut builder = tempfile::Builder::new();
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        builder.permissions(std::fs::Permissions::from_mode(0o666));
    }
    builder.tempfile_in(dir).map_err(|e| {
        // tempfile appends ` at path "<dir>/.tmpXXXX"` to the system's words.
        let said = e.to_string();
        match said.split_once(" at path \"") {
            Some((system, _)) => std::io::Error::new(e.kind(), system.to_string()),
            None => e,
        }
    })
}
