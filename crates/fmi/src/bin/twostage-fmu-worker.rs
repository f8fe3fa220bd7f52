//! A worker process for FMUs that may be instantiated only once per
//! process, for programs that cannot serve their own (a test harness):
//! `FmuSimulatorBuilder::worker_processes` names it, and the simulator
//! starts it with `TWOSTAGE_FMU_WORKER` set. People do not run it by hand.

use std::process::ExitCode;

fn main() -> ExitCode {
    // Serves and exits when started as a worker.
    twostage_fmi::serve_workers_from_this_program();
    eprintln!(
        "error: twostage-fmu-worker serves an FMU simulator that starts it (with \
         TWOSTAGE_FMU_WORKER set); it is not run by hand"
    );
    ExitCode::from(2)
}
