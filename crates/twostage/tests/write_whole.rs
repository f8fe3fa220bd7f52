//! `write_whole` replaces regular files whole, and writes through what is
//! not one: a FIFO (standing in for `/dev/null`, which a test cannot
//! safely break) stays a FIFO and receives the bytes.
// A panic is how a test fails.
#![allow(clippy::unwrap_used)]
#![cfg(unix)]

use std::os::unix::fs::FileTypeExt;

#[test]
fn a_fifo_is_written_through_not_replaced_by_a_file() {
    let dir = tempfile::tempdir().unwrap();
    let fifo = dir.path().join("pipe");
    let made = std::process::Command::new("mkfifo")
        .arg(&fifo)
        .status()
        .unwrap();
    assert!(made.success());
    let reader = {
        let fifo = fifo.clone();
        std::thread::spawn(move || std::fs::read(fifo).unwrap())
    };
    twostage::write_whole(&fifo, b"estimates\n").unwrap();
    assert_eq!(reader.join().unwrap(), b"estimates\n");
    let kind = std::fs::symlink_metadata(&fifo).unwrap().file_type();
    assert!(kind.is_fifo(), "the FIFO was replaced: {kind:?}");
}

#[test]
fn a_symbolic_link_keeps_pointing_at_the_file_it_named() {
    let dir = tempfile::tempdir().unwrap();
    let real = dir.path().join("real.csv");
    let link = dir.path().join("link.csv");
    std::fs::write(&real, b"old").unwrap();
    std::os::unix::fs::symlink(&real, &link).unwrap();
    twostage::write_whole(&link, b"new").unwrap();
    assert!(
        std::fs::symlink_metadata(&link)
            .unwrap()
            .file_type()
            .is_symlink()
    );
    assert_eq!(std::fs::read(&real).unwrap(), b"new");
}

#[test]
fn a_folder_is_refused_by_name() {
    let dir = tempfile::tempdir().unwrap();
    let error = twostage::write_whole(dir.path(), b"x").unwrap_err();
    assert!(
        error
            .to_string()
            .contains(&dir.path().display().to_string()),
        "{error}"
    );
    assert!(dir.path().is_dir());
}

/// A new file gets the mode `std::fs::write` gives one beside it (not a
/// temporary file's owner-only 0600); a replaced file keeps its
/// own.
#[test]
fn a_written_file_has_the_mode_an_ordinary_write_gives() {
    use std::os::unix::fs::PermissionsExt;
    let dir = tempfile::tempdir().unwrap();
    let mode = |p: &std::path::Path| std::fs::metadata(p).unwrap().permissions().mode() & 0o777;
    let plain = dir.path().join("plain.txt");
    std::fs::write(&plain, b"x").unwrap();
    let whole = dir.path().join("whole.tsest");
    twostage::write_whole(&whole, b"estimator").unwrap();
    assert_eq!(mode(&whole), mode(&plain));
    std::fs::set_permissions(&whole, std::fs::Permissions::from_mode(0o640)).unwrap();
    twostage::write_whole(&whole, b"estimator, again").unwrap();
    assert_eq!(mode(&whole), 0o640);
    assert_eq!(std::fs::read(&whole).unwrap(), b"estimator, again");
}
