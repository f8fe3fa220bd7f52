//! Worker processes for FMUs that may be instantiated only once per
//! process (`canBeInstantiatedOnlyOncePerProcess`): each worker holds one
//! instance and runs the experiments the parent sends it.
//!
//! The parent draws every random number (inputs and noise) from the
//! experiment's stream and sends them with the parameters; the worker runs
//! the FMU exactly as the in-process simulator does and sends the outputs
//! back. A chart is therefore the same bits with workers, threads, or one
//! experiment at a time.
//!
//! Messages are postcard frames behind an 8-byte marker and a length. The
//! parent skips anything before a marker, so an FMU that prints to stdout
//! cannot break the conversation.

use std::io::{BufReader, Read, Write};
use std::process::{Child, ChildStdin, ChildStdout, Command, Stdio};
use std::sync::{Mutex, OnceLock, PoisonError};

use twostage_models::IoData;

use crate::error::{FmiError, Result};
use crate::setup::{Loaded, Setup};

/// Starts every frame.
const MARKER: &[u8; 8] = b"TSFMUwk1";
/// Set in a worker's environment by the parent that starts it: the one
/// way a program learns that it is to serve as a worker.
const WORKER_ENV: &str = "TWOSTAGE_FMU_WORKER";

/// This program, when it said it can serve workers
/// ([`serve_workers_from_this_program`]).
static THIS_PROGRAM: OnceLock<Vec<String>> = OnceLock::new();

/// Make this program the worker of FMUs that may be instantiated only once
/// per process. Call it first thing in `main`: started as a worker (by a
/// parent that set `TWOSTAGE_FMU_WORKER`), it serves the parent on stdin
/// and stdout and exits the process; otherwise it returns at once, and
/// such FMUs then run in worker processes of this very program instead of
/// one experiment at a time in this one. A program that never calls it
/// keeps them in process (a builder may still name a worker program,
/// [`FmuSimulatorBuilder::worker_processes`](crate::FmuSimulatorBuilder::worker_processes)).
///
/// ```
/// // First thing in `main`; then the program, whose FMU simulators may
/// // now use workers.
/// twostage_fmi::serve_workers_from_this_program();
/// ```
pub fn serve_workers_from_this_program() {
    if std::env::var_os(WORKER_ENV).is_some() {
        let served = serve_worker(std::io::stdin().lock(), std::io::stdout().lock());
        if let Err(e) = &served {
            eprintln!("error: {e}");
        }
        std::process::exit(i32::from(served.is_err()));
    }
    if let Ok(exe) = std::env::current_exe() {
        let _ = THIS_PROGRAM.set(vec![exe.display().to_string()]);
    }
}

/// The worker program of this process, if it can serve workers.
pub(crate) fn this_program() -> Option<Vec<String>> {
    THIS_PROGRAM.get().cloned()
}
/// The largest frame accepted (a record of 2^27 values).
const MAX_FRAME: usize = 1 << 30;

#[derive(serde::Serialize, serde::Deserialize)]
enum ToWorker {
    Setup(Setup),
    Run {
        theta: Vec<f64>,
        /// The record's length (a given input's may differ from the
        /// model's).
        samples: usize,
        /// Each input's samples in turn.
        inputs: Vec<f64>,
        /// The noise inputs, sample by sample.
        noise: Vec<f64>,
    },
}

#[derive(serde::Serialize, serde::Deserialize)]
enum FromWorker {
    Ready,
    /// Each output's samples in turn.
    Outputs(Vec<f64>),
    /// The experiment failed; `retire`: this worker cannot run the FMU
    /// again (it returned Fatal) and exits.
    Failed {
        message: String,
        retire: bool,
    },
}

fn write_frame<T: serde::Serialize>(writer: &mut impl Write, message: &T) -> std::io::Result<()> {
    let payload = postcard::to_stdvec(message).map_err(std::io::Error::other)?;
    let length =
        u32::try_from(payload.len()).map_err(|_| std::io::Error::other("a frame over 4 GiB"))?;
    writer.write_all(MARKER)?;
    writer.write_all(&length.to_le_bytes())?;
    writer.write_all(&payload)?;
    writer.flush()
}

/// The next frame, skipping anything before its marker; `None` at the end
/// of the stream.
fn read_frame<T: serde::de::DeserializeOwned>(
    reader: &mut impl Read,
) -> std::io::Result<Option<T>> {
    let mut matched = 0;
    let mut byte = [0u8; 1];
    while matched < MARKER.len() {
        if reader.read(&mut byte)? == 0 {
            return if matched == 0 {
                Ok(None)
            } else {
                Err(std::io::ErrorKind::UnexpectedEof.into())
            };
        }
        matched = if byte[0] == MARKER[matched] {
            matched + 1
        } else {
            usize::from(byte[0] == MARKER[0])
        };
    }
    let mut length = [0u8; 4];
    reader.read_exact(&mut length)?;
    let length = u32::from_le_bytes(length) as usize;
    if length > MAX_FRAME {
        return Err(std::io::Error::other(format!("a frame of {length} bytes")));
    }
    let mut payload = vec![0u8; length];
    reader.read_exact(&mut payload)?;
    postcard::from_bytes(&payload)
        .map(Some)
        .map_err(std::io::Error::other)
}

/// Serve a parent's experiments: the body of a worker process. Reads the
/// set-up and then experiments from `input`, answers on `output`, and
/// returns at the end of `input`.
///
/// [`serve_workers_from_this_program`] calls it in a worker process.
///
/// # Errors
/// Only when the pipes fail; every FMU failure is sent to the parent.
pub fn serve_worker(input: impl Read, output: impl Write) -> Result<()> {
    let mut input = BufReader::new(input);
    let mut output = std::io::BufWriter::new(output);
    let pipe = |e: std::io::Error| FmiError::Worker {
        path: "-".into(),
        message: format!("the pipe to the parent failed: {e}"),
    };
    let Some(ToWorker::Setup(setup)) = read_frame(&mut input).map_err(pipe)? else {
        return Err(FmiError::Worker {
            path: "-".into(),
            message: "the parent did not start with a set-up".into(),
        });
    };
    let ready = Loaded::open(&setup).and_then(|loaded| {
        let engine = loaded.in_process(true)?;
        Ok((loaded, engine))
    });
    let (loaded, engine) = match ready {
        Ok(ready) => ready,
        Err(e) => {
            let failed = FromWorker::Failed {
                message: e.to_string(),
                retire: true,
            };
            write_frame(&mut output, &failed).map_err(pipe)?;
            return Ok(());
        }
    };
    write_frame(&mut output, &FromWorker::Ready).map_err(pipe)?;
    let (n_u, n_y) = (setup.inputs.len(), setup.outputs.len());
    let mut record = IoData::zeros(setup.n_samples, n_u, n_y);
    while let Some(message) = read_frame::<ToWorker>(&mut input).map_err(pipe)? {
        let ToWorker::Run {
            theta,
            samples: n,
            inputs,
            noise,
        } = message
        else {
            continue;
        };
        record.resize(n, n_u, n_y);
        let reply = if inputs.len() != n * n_u {
            FromWorker::Failed {
                message: format!(
                    "{} input values for {n} samples of {n_u} inputs",
                    inputs.len()
                ),
                retire: false,
            }
        } else {
            for j in 0..n_u {
                record
                    .input_mut(j)
                    .copy_from_slice(&inputs[j * n..(j + 1) * n]);
            }
            match engine.run(&loaded.plan, &theta, &noise, &mut record) {
                Ok(()) => FromWorker::Outputs(
                    (0..n_y)
                        .flat_map(|j| record.output(j).iter().copied())
                        .collect(),
                ),
                Err(e) => FromWorker::Failed {
                    message: e.to_string(),
                    retire: engine.is_fatal(),
                },
            }
        };
        write_frame(&mut output, &reply).map_err(pipe)?;
        if engine.is_fatal() {
            // A fresh process loads the FMU afresh; this one cannot.
            return Ok(());
        }
    }
    Ok(())
}

/// One worker process.
struct WorkerProcess {
    child: Child,
    /// Closed first when the worker is let go.
    stdin: Option<ChildStdin>,
    stdout: BufReader<ChildStdout>,
}

/// How long a worker let go may take to end (unload its FMU) before it is
/// killed.
const WORKER_GRACE: std::time::Duration = std::time::Duration::from_secs(5);

impl Drop for WorkerProcess {
    fn drop(&mut self) {
        // Its input closed, a worker ends its loop and unloads its FMU.
        // One that hangs (a crashed FMU) is killed after the grace period.
        drop(self.stdin.take());
        let start = std::time::Instant::now();
        while start.elapsed() < WORKER_GRACE {
            if !matches!(self.child.try_wait(), Ok(None)) {
                return;
            }
            std::thread::sleep(std::time::Duration::from_millis(5));
        }
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// The worker processes of one simulator: one per concurrent caller.
pub(crate) struct WorkerPool {
    command: Vec<String>,
    /// The set-up each worker gets: the FMU the parent unpacked, so that a
    /// worker unpacks nothing and a crashed one leaves nothing behind.
    setup: Setup,
    /// The FMU as the user named it, and where the parent unpacked it (the
    /// workers' name for it, replaced by the user's in their messages).
    origin: String,
    unpacked_at: String,
    idle: Mutex<Vec<WorkerProcess>>,
}

impl WorkerPool {
    /// Start one worker on the FMU the parent unpacked at `unpacked_at`,
    /// so that a failing set-up is reported now.
    pub fn start(
        command: Vec<String>,
        setup: &Setup,
        origin: &str,
        unpacked_at: &std::path::Path,
    ) -> Result<Self> {
        if command.first().is_none_or(|c| c.trim().is_empty()) {
            return Err(FmiError::Setting {
                name: "worker command",
                value: format!("{command:?}"),
                reason: "give the program and its arguments".into(),
            });
        }
        let pool = Self {
            command,
            setup: Setup {
                path: unpacked_at.to_path_buf(),
                ..setup.clone()
            },
            origin: origin.into(),
            unpacked_at: unpacked_at.display().to_string(),
            idle: Mutex::new(Vec::new()),
        };
        let first = pool.spawn()?;
        pool.idle
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .push(first);
        Ok(pool)
    }

    fn fail(&self, message: String) -> FmiError {
        FmiError::Worker {
            path: self.origin.clone(),
            message,
        }
    }

    fn spawn(&self) -> Result<WorkerProcess> {
        let mut child = Command::new(&self.command[0])
            .args(&self.command[1..])
            .env(WORKER_ENV, "1")
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit())
            .spawn()
            .map_err(|e| self.fail(format!("`{}` does not start: {e}", self.command.join(" "))))?;
        let (Some(stdin), Some(stdout)) = (child.stdin.take(), child.stdout.take()) else {
            return Err(self.fail("no pipes to the worker".into()));
        };
        let mut worker = WorkerProcess {
            child,
            stdin: Some(stdin),
            stdout: BufReader::new(stdout),
        };
        match self.call(&mut worker, &ToWorker::Setup(self.setup.clone()))? {
            FromWorker::Ready => Ok(worker),
            FromWorker::Failed { message, .. } => Err(self.fail(self.unprefixed(message))),
            FromWorker::Outputs(_) => Err(self.fail("answered the set-up with outputs".into())),
        }
    }

    /// Send one message and wait for the answer.
    fn call(&self, worker: &mut WorkerProcess, message: &ToWorker) -> Result<FromWorker> {
        let sent = match worker.stdin.as_mut() {
            Some(stdin) => write_frame(stdin, message),
            None => Err(std::io::Error::from(std::io::ErrorKind::BrokenPipe)),
        };
        let answer = sent.and_then(|()| read_frame(&mut worker.stdout));
        match answer {
            Ok(Some(reply)) => Ok(reply),
            Ok(None) | Err(_) => {
                let status = worker
                    .child
                    .wait()
                    .map_or_else(|e| e.to_string(), |s| s.to_string());
                Err(self.fail(format!(
                    "`{}` ended without an answer ({status}): the FMU may have crashed; the next \
                     experiment starts a new worker",
                    self.command.join(" ")
                )))
            }
        }
    }

    /// The worker's message without the FMU path it starts with.
    fn unprefixed(&self, message: String) -> String {
        let message = message.replace(&self.unpacked_at, &self.origin);
        message
            .strip_prefix(&format!("{}: ", self.origin))
            .map(str::to_string)
            .unwrap_or(message)
    }

    /// Run one experiment in a worker: `out` holds the inputs and receives
    /// the outputs.
    pub fn run(&self, theta: &[f64], noise: &[f64], out: &mut IoData) -> Result<()> {
        let idle = self
            .idle
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .pop();
        let mut worker = match idle {
            Some(worker) => worker,
            None => self.spawn()?,
        };
        let (n, n_y) = (out.n_samples(), out.n_outputs());
        let message = ToWorker::Run {
            theta: theta.to_vec(),
            samples: n,
            inputs: (0..out.n_inputs())
                .flat_map(|j| out.input(j).iter().copied())
                .collect(),
            noise: noise.to_vec(),
        };
        // A worker that did not answer is dropped (killed) here.
        let reply = self.call(&mut worker, &message)?;
        let mut retire = false;
        let result = match reply {
            FromWorker::Outputs(y) if y.len() == n * n_y => {
                for j in 0..n_y {
                    out.output_mut(j).copy_from_slice(&y[j * n..(j + 1) * n]);
                }
                Ok(())
            }
            FromWorker::Outputs(y) => Err(self.fail(format!(
                "{} output values for {n} samples of {n_y} outputs",
                y.len()
            ))),
            FromWorker::Failed { message, retire: r } => {
                retire = r;
                Err(self.fail(self.unprefixed(message)))
            }
            FromWorker::Ready => Err(self.fail("answered an experiment with `ready`".into())),
        };
        if !retire {
            self.idle
                .lock()
                .unwrap_or_else(PoisonError::into_inner)
                .push(worker);
        }
        result
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frames_survive_text_printed_before_and_between_them() {
        let mut stream = Vec::new();
        stream.extend_from_slice(b"FMU says hello\nTSFMU");
        write_frame(&mut stream, &FromWorker::Outputs(vec![1.5, -2.0])).unwrap();
        stream.extend_from_slice(b"TSFMUwk");
        let failed = FromWorker::Failed {
            message: "no".into(),
            retire: true,
        };
        write_frame(&mut stream, &failed).unwrap();
        let mut reader = &stream[..];
        let first: FromWorker = read_frame(&mut reader).unwrap().unwrap();
        assert!(
            matches!(first, FromWorker::Outputs(y) if y.len() == 2 && y[1].to_bits() == (-2.0f64).to_bits())
        );
        let second: FromWorker = read_frame(&mut reader).unwrap().unwrap();
        assert!(matches!(second, FromWorker::Failed { message, retire: true } if message == "no"));
        assert!(read_frame::<FromWorker>(&mut reader).unwrap().is_none());
    }

    #[test]
    fn a_stream_cut_inside_a_frame_is_an_error_not_a_frame() {
        let mut stream = Vec::new();
        write_frame(&mut stream, &FromWorker::Outputs(vec![1.0; 10])).unwrap();
        stream.truncate(stream.len() - 3);
        assert!(read_frame::<FromWorker>(&mut &stream[..]).is_err());
        assert!(read_frame::<FromWorker>(&mut &b"TSFM"[..]).is_err());
    }
}
