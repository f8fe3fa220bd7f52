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
            // `extract` refuses entries that would land outside the folder.
            archive
                .extract(temporary.path())
                .map_err(|e| FmiError::NotAnArchive {
                    path: origin.clone(),
                    message: format!("it cannot be unpacked ({e})"),
                })?;
            (temporary.path().to_path_buf(), Some(temporary))
        };
        let description_path = root.join("modelDescription.xml");
        let text = std::fs::read_to_string(&description_path).map_err(|e| {
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
