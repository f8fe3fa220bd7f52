//! Puts memory.x on the linker's path and the test's cases into the
//! firmware: TWOSTAGE_FIRMWARE_DATA names a folder of `case-K.tsrt` (an
//! exported estimator) and `case-K.bin` (records) files, K = 0, 1, ...

use std::fmt::Write as _;
use std::path::PathBuf;

fn main() {
    let out = PathBuf::from(std::env::var("OUT_DIR").expect("cargo sets OUT_DIR"));
    std::fs::copy("memory.x", out.join("memory.x")).expect("memory.x is beside build.rs");
    println!("cargo:rustc-link-search={}", out.display());
    println!("cargo:rerun-if-changed=memory.x");
    println!("cargo:rerun-if-env-changed=TWOSTAGE_FIRMWARE_DATA");
    let data = std::env::var("TWOSTAGE_FIRMWARE_DATA").expect(
        "set TWOSTAGE_FIRMWARE_DATA to a folder of case-K.tsrt and case-K.bin files \
         (crates/runtime/tests/qemu.rs writes one)",
    );
    let mut cases = String::from("pub static CASES: &[(&[u8], &[u8])] = &[\n");
    for k in 0.. {
        let blob = PathBuf::from(&data).join(format!("case-{k}.tsrt"));
        let records = PathBuf::from(&data).join(format!("case-{k}.bin"));
        if !blob.exists() {
            break;
        }
        println!("cargo:rerun-if-changed={}", blob.display());
        println!("cargo:rerun-if-changed={}", records.display());
        writeln!(
            cases,
            "    (include_bytes!({:?}), include_bytes!({:?})),",
            blob.display().to_string(),
            records.display().to_string()
        )
        .expect("writing to a string");
    }
    cases.push_str("];\n");
    std::fs::write(out.join("cases.rs"), cases).expect("OUT_DIR is writable");
}
