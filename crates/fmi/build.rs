//! Compile the C half of the FMI 2.0 logger: FMI 2.0 hands the importer a
//! printf-style message with variadic arguments, which only C can format
//! (stable Rust cannot define a variadic function).

fn main() {
    println!("cargo::rerun-if-changed=src/logger.c");
    cc::Build::new()
        .file("src/logger.c")
        .warnings(true)
        .compile("twostage_fmi_logger");
}
