//! The FMU archive: a zip file (or a folder already unpacked) holding
//! `modelDescription.xml`, `binaries/<platform>/` and `resources/`
//! (FMI 2.0 section 2.3, FMI 3.0 section 2.5).

use std::path::{Path, PathBuf};

use crate::description::{FmiVersion, ModelDescription};
use crate::error::{FmiError, Result};

/// An FMU on disk, unpacked: its folder and its description.
#[derive(Debug)]
pub(crate) struct Unpacked {
    /// The FMU as the user named it.
    pub origin: String,
    /// The unpacked folder (a temporary one for an archive, removed on drop).
    pub root: PathBuf,
    pub description: ModelDescription,
    /// Keeps a temporary folder alive as long as the FMU.
    _temporary: Option<tempfile::TempDir>,
}

impl Unpacked {
    /// Unpack `path` (a `.fmu` archive, or a folder holding an unpacked
    /// FMU) and read its description.
    pub fn open(path: &Path) -> Result<Self> {
        let origin = path.display().to_string();
        let io = |e: std::io::Error| FmiError::Io {
            path: origin.clone(),
            message: e.to_string(),
        };
        let (root, temporary) = if path.is_dir() {
            (path.to_path_buf(), None)
        } else {
            let mut file = std::fs::File::open(path).map_err(io)?;
            let mut magic = [0u8; 4];
            let read = std::io::Read::read(&mut file, &mut magic).map_err(io)?;
            if read < 4 || &magic != b"PK\x03\x04" {
                return Err(FmiError::NotAnArchive {
                    path: origin,
                    message: "it does not start like a zip archive".into(),
                });
            }
            let mut archive = zip::ZipArchive::new(file).map_err(|e| FmiError::NotAnArchive {
                path: origin.clone(),
                message: format!("the zip archive is damaged ({e})"),
            })?;
            let temporary = tempfile::Builder::new()
                .prefix("twostage-fmu-")
                .tempdir()
                .map_err(io)?;
            let room = twostage_models::free_disk(temporary.path()).unwrap_or(u64::MAX);
            unpack(&mut archive, temporary.path(), room).map_err(|failed| match failed {
                Unpacking::NoRoom(message) => FmiError::NoRoom {
                    path: origin.clone(),
                    message,
                },
                Unpacking::Damaged(message) => FmiError::NotAnArchive {
                    path: origin.clone(),
                    message,
                },
            })?;
            (temporary.path().to_path_buf(), Some(temporary))
        };
        let description_path = root.join("modelDescription.xml");
        let text = read_description(&description_path).map_err(|e| {
            if e.kind() == std::io::ErrorKind::NotFound {
                FmiError::Description {
                    path: origin.clone(),
                    line: None,
                    message: "the FMU holds no modelDescription.xml at its top level".into(),
                }
            } else {
                io(e)
            }
        })?;
        let description = ModelDescription::parse(&text, &origin)?;
        Ok(Self {
            origin,
            root,
            description,
            _temporary: temporary,
        })
    }

    /// The shared library for this platform, for `model_identifier`.
    pub fn binary(&self, model_identifier: &str) -> Result<PathBuf> {
        let platform = platform_folder(self.description.version);
        let file = format!("{model_identifier}{}", std::env::consts::DLL_SUFFIX);
        let path = self.root.join("binaries").join(&platform).join(&file);
        if path.is_file() {
            return Ok(path);
        }
        let found = std::fs::read_dir(self.root.join("binaries"))
            .map(|entries| {
                let mut names: Vec<String> = entries
                    .filter_map(|e| e.ok())
                    .map(|e| e.file_name().to_string_lossy().into_owned())
                    .collect();
                names.sort();
                names
            })
            .unwrap_or_default();
        Err(FmiError::NoBinary {
            path: self.origin.clone(),
            expected: format!("binaries/{platform}/{file}"),
            found: if found.is_empty() {
                "no binaries at all".into()
            } else {
                format!("binaries for {}", found.join(", "))
            },
        })
    }

    /// Where the FMU's resources are, as its FMI version wants to be told:
    /// a `file:` URI for FMI 2.0, a folder path ending in a separator for
    /// FMI 3.0.
    pub fn resource_location(&self) -> String {
        let resources = self.root.join("resources");
        let absolute = std::path::absolute(&resources).unwrap_or(resources);
        match self.description.version {
            FmiVersion::V2 => format!("file://{}", percent_encode(&absolute.to_string_lossy())),
            FmiVersion::V3 => format!("{}{}", absolute.display(), std::path::MAIN_SEPARATOR),
        }
    }
}

/// The largest `modelDescription.xml` read: a description of a hundred
/// thousand variables takes tens of megabytes; beyond this a file is not
/// a description but an attack on the memory.
const MAX_DESCRIPTION_BYTES: u64 = 256 << 20;

/// `modelDescription.xml`'s text, refused beyond [`MAX_DESCRIPTION_BYTES`]
/// before it is read.
fn read_description(path: &Path) -> std::io::Result<String> {
    use std::io::Read;
    let file = std::fs::File::open(path)?;
    let size = file.metadata()?.len();
    if size > MAX_DESCRIPTION_BYTES {
        return Err(std::io::Error::other(format!(
            "modelDescription.xml takes {} where a description takes at most {}: \
             the FMU is damaged or not an FMU",
            twostage_models::readable_bytes(size as f64),
            twostage_models::readable_bytes(MAX_DESCRIPTION_BYTES as f64)
        )));
    }
    let mut text = String::new();
    file.take(MAX_DESCRIPTION_BYTES).read_to_string(&mut text)?;
    Ok(text)
}

/// Why an archive was not unpacked.
#[derive(Debug)]
enum Unpacking {
    /// Its entries would take more than the room there is.
    NoRoom(String),
    /// It is damaged or forged.
    Damaged(String),
}

/// Unpack every entry of `archive` into `folder`, with no more than
/// `room` bytes written: the entries' declared sizes are summed before
/// anything is written (a zip bomb declares what it unpacks to), and an
/// entry that unpacks to more than it declares is stopped there. Entries
/// that would land outside the folder are refused; links are written as
/// the files they hold.
fn unpack(
    archive: &mut zip::ZipArchive<std::fs::File>,
    folder: &Path,
    room: u64,
) -> std::result::Result<(), Unpacking> {
    use std::io::Read;
    let mut declared = 0u64;
    for i in 0..archive.len() {
        let entry = archive
            .by_index_raw(i)
            .map_err(|e| Unpacking::Damaged(format!("entry {i} cannot be read ({e})")))?;
        declared = declared.saturating_add(entry.size());
    }
    if declared > room {
        return Err(Unpacking::NoRoom(format!(
            "it unpacks to {} (its entries' sizes), where the disk of {} has {} free: \
             free room there or set TMPDIR to a disk with more",
            twostage_models::readable_bytes(declared as f64),
            folder.display(),
            twostage_models::readable_bytes(room as f64)
        )));
    }
    for i in 0..archive.len() {
        let mut entry = archive
            .by_index(i)
            .map_err(|e| Unpacking::Damaged(format!("entry {i} cannot be unpacked ({e})")))?;
        let name = entry
            .name()
            .map_or_else(|_| format!("number {i}"), |name| format!("{name:?}"));
        let Some(relative) = entry.enclosed_name() else {
            return Err(Unpacking::Damaged(format!(
                "entry {name} would land outside the folder it is unpacked into"
            )));
        };
        let path = folder.join(relative);
        let made = |e: std::io::Error| Unpacking::Damaged(format!("{}: {e}", path.display()));
        if entry.is_dir() {
            std::fs::create_dir_all(&path).map_err(made)?;
            continue;
        }
        if let Some(parent) = path.parent() {
            std::fs::create_dir_all(parent).map_err(made)?;
        }
        let size = entry.size();
        let mut out = std::fs::File::create(&path).map_err(made)?;
        let written = std::io::copy(&mut (&mut entry).take(size.saturating_add(1)), &mut out)
            .map_err(|e| Unpacking::Damaged(format!("entry {name} cannot be unpacked ({e})")))?;
        if written > size {
            return Err(Unpacking::Damaged(format!(
                "entry {name} unpacks to more than the {size} bytes it declares: the archive \
                 is damaged or forged"
            )));
        }
    }
    Ok(())
}

/// The folder under `binaries/` that holds this platform's shared library:
/// FMI 2.0 names (`linux64`, `win64`, `darwin64`; FMI 2.0.4 section 2.3)
/// and FMI 3.0 platform tuples (`x86_64-linux`; FMI 3.0.1 section 2.5.1.4).
///
/// ```
/// use twostage_fmi::{platform_folder, FmiVersion};
/// if cfg!(all(target_os = "linux", target_arch = "x86_64")) {
///     assert_eq!(platform_folder(FmiVersion::V3), "x86_64-linux");
/// }
/// ```
pub fn platform_folder(version: FmiVersion) -> String {
    let os = match std::env::consts::OS {
        "macos" => "darwin",
        other => other,
    };
    match version {
        FmiVersion::V2 => {
            let bits = if cfg!(target_pointer_width = "64") {
                "64"
            } else {
                "32"
            };
            format!("{os}{bits}")
        }
        FmiVersion::V3 => format!("{}-{os}", std::env::consts::ARCH),
    }
}

/// Percent-encode what a URI path cannot hold literally (RFC 3986,
/// section 2.1); `/` stays.
fn percent_encode(path: &str) -> String {
    let mut out = String::with_capacity(path.len());
    for byte in path.bytes() {
        if byte.is_ascii_alphanumeric() || b"/-._~".contains(&byte) {
            out.push(char::from(byte));
        } else {
            out.push_str(&format!("%{byte:02X}"));
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A zip archive of `entries` (name, bytes), deflated, as a file.
    fn archive_of(
        entries: &[(&str, &[u8])],
    ) -> (tempfile::TempDir, zip::ZipArchive<std::fs::File>) {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("a.fmu");
        write_zip(&path, entries);
        let archive = zip::ZipArchive::new(std::fs::File::open(&path).unwrap()).unwrap();
        (dir, archive)
    }

    fn write_zip(path: &Path, entries: &[(&str, &[u8])]) {
        use std::io::Write;
        let mut writer = zip::ZipWriter::new(std::fs::File::create(path).unwrap());
        let options = zip::write::SimpleFileOptions::default()
            .compression_method(zip::CompressionMethod::Deflated);
        for (name, bytes) in entries {
            writer.start_file(*name, options).unwrap();
            writer.write_all(bytes).unwrap();
        }
        writer.finish().unwrap();
    }

    fn files_in(folder: &Path) -> usize {
        std::fs::read_dir(folder).unwrap().count()
    }

    #[test]
    fn a_zip_bomb_is_refused_by_its_declared_size_before_anything_is_written() {
        // 20 MB of zeros deflate to about 20 kB.
        let zeros = vec![0u8; 20_000_000];
        let (dir, mut archive) = archive_of(&[("a.txt", b"a"), ("zeros.bin", &zeros)]);
        assert!(std::fs::metadata(dir.path().join("a.fmu")).unwrap().len() < 100_000);
        let into = tempfile::tempdir().unwrap();
        let Err(Unpacking::NoRoom(refused)) = unpack(&mut archive, into.path(), 1_000_000) else {
            panic!("a bomb was unpacked");
        };
        assert!(
            refused.starts_with("it unpacks to 20.0 MB (its entries' sizes), where the disk of")
                && refused.contains("has 1.0 MB free"),
            "{refused}"
        );
        assert_eq!(files_in(into.path()), 0);
        // With room, the same archive unpacks whole.
        unpack(&mut archive, into.path(), 100_000_000).unwrap();
        assert_eq!(std::fs::read(into.path().join("zeros.bin")).unwrap(), zeros);
    }

    #[test]
    fn an_entry_larger_than_it_declares_is_stopped_at_its_declared_size() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("forged.fmu");
        let text = vec![b'a'; 100_000];
        write_zip(&path, &[("big.txt", &text)]);
        // Forge the uncompressed size in the local header (offset 22 from
        // its signature) and the central directory (offset 24) to 1000.
        let mut bytes = std::fs::read(&path).unwrap();
        let forge = |bytes: &mut Vec<u8>, signature: &[u8; 4], offset: usize| {
            let at = bytes.windows(4).position(|w| w == signature).unwrap();
            bytes[at + offset..at + offset + 4].copy_from_slice(&1000u32.to_le_bytes());
        };
        forge(&mut bytes, b"PK\x03\x04", 22);
        forge(&mut bytes, b"PK\x01\x02", 24);
        std::fs::write(&path, &bytes).unwrap();
        let mut archive = zip::ZipArchive::new(std::fs::File::open(&path).unwrap()).unwrap();
        let into = tempfile::tempdir().unwrap();
        let Err(Unpacking::Damaged(refused)) = unpack(&mut archive, into.path(), u64::MAX) else {
            panic!("a forged entry was unpacked");
        };
        assert!(
            refused.starts_with("entry \"big.txt\" ") && refused.contains("declared"),
            "{refused}"
        );
        let written = std::fs::metadata(into.path().join("big.txt")).map_or(0, |m| m.len());
        assert!(written <= 1001, "{written}");
    }

    #[test]
    fn an_entry_that_would_land_outside_the_folder_is_refused() {
        let (_dir, mut archive) = archive_of(&[("../outside.txt", b"x")]);
        let into = tempfile::tempdir().unwrap();
        let Err(Unpacking::Damaged(refused)) =
            unpack(&mut archive, &into.path().join("fmu"), u64::MAX)
        else {
            panic!("an entry outside the folder was unpacked");
        };
        assert!(refused.contains("would land outside"), "{refused}");
        assert!(!into.path().join("outside.txt").exists());
    }

    #[test]
    fn uri_paths_escape_spaces_and_keep_slashes() {
        assert_eq!(percent_encode("/tmp/my fmu/r%s"), "/tmp/my%20fmu/r%25s");
    }

    #[test]
    fn platform_folders_follow_each_standard() {
        if cfg!(all(target_os = "linux", target_arch = "x86_64")) {
            assert_eq!(platform_folder(FmiVersion::V2), "linux64");
            assert_eq!(platform_folder(FmiVersion::V3), "x86_64-linux");
        }
    }
}
