//! The committed C header is the one cbindgen makes from the C API today
//! (`TWOSTAGE_BLESS=1` rewrites it).

#![allow(clippy::unwrap_used)]

use std::path::Path;

#[test]
fn the_committed_header_is_current() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR"));
    let config = cbindgen::Config::from_file(dir.join("cbindgen.toml")).unwrap();
    let mut generated = Vec::new();
    cbindgen::Builder::new()
        .with_crate(dir)
        .with_config(config)
        .generate()
        .unwrap()
        .write(&mut generated);
    let generated = String::from_utf8(generated).unwrap();
    let path = dir.join("include/twostage_rt.h");
    if std::env::var_os("TWOSTAGE_BLESS").is_some() {
        std::fs::write(&path, &generated).unwrap();
    }
    let committed = std::fs::read_to_string(&path).unwrap_or_default();
    assert!(
        committed == generated,
        "{} is stale: the C API changed. Regenerate it with \
         TWOSTAGE_BLESS=1 cargo test -p twostage-runtime-c --test header, and commit it",
        path.display()
    );
}
