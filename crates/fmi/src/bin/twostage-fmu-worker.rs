//! A worker process for FMUs that may be instantiated only once per
//! process: `FmuSimulator` starts it and talks to it over stdin and stdout
//! (`twostage_fmi::serve_worker`); people do not run it by hand.

use std::process::ExitCode;

fn main() -> ExitCode {
    match twostage_fmi::serve_worker(std::io::stdin().lock(), std::io::stdout().lock()) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::FAILURE
        }
    }
}
