//! External simulators: any program, in any language, that speaks the
//! line-based protocol of docs/protocol.md on its standard input and output.
//! Each worker thread gets its own long-lived process; a process that
//! crashes, hangs past the timeout or answers out of protocol is killed, its
//! experiment fails with an error quoting the answer, and the next
//! experiment starts a fresh process.

use crate::InvalidSetting;
use std::fmt::Write as _;
use std::path::PathBuf;
use std::process::{Command, Stdio};
use std::sync::{Mutex, PoisonError};
use std::time::{Duration, Instant};

use crate::data::IoData;
use crate::error::{Result, SimError};
use crate::external_process::Process;
use crate::rng::ExperimentRng;
use crate::simulator::{
    Block, BlockInputs, Capabilities, Conditions, ModelSpec, Simulator, check_theta,
};

/// The newest protocol version this build speaks (the second word of the
/// greeting); a model file chooses it with `protocol = 2`, and version 1
/// is still served for the simulators written for it.
pub const PROTOCOL_VERSION: u32 = 2;

/// What a simulator answered for one experiment, in protocol.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum ProtocolAnswer {
    /// Its record, read whole.
    Record,
    /// `error INDEX MESSAGE`: the experiment failed, with the message.
    Failed(String),
}

/// One experiment of a batch request.
#[derive(Debug, Clone, Copy)]
pub struct ExternalJob<'a> {
    /// The experiment's index in its chart.
    pub index: u64,
    /// The seed the simulator draws the experiment's randomness from,
    /// together with the index.
    pub seed: u64,
    /// The parameter vector.
    pub theta: &'a [f64],
}

impl ExternalJob<'_> {
    /// The index and seed that the experiment stream `rng` stands for: its
    /// ChaCha stream number and the first eight bytes of its key. A chart's
    /// experiment `i` of seed `s` always gets the same pair, so an external
    /// simulator that draws from them keeps charts reproducible.
    pub fn stream_of(rng: &ExperimentRng) -> (u64, u64) {
        let key = rng.get_seed();
        let mut seed = [0u8; 8];
        seed.copy_from_slice(&key[..8]);
        (rng.get_stream(), u64::from_le_bytes(seed))
    }
}

/// A simulator that is another program (docs/protocol.md).
///
/// | setting | default | valid |
/// |---|---|---|
/// | `timeout` | 60 s | > 0: per record, and for the greeting |
/// | `batch` | 1 | >= 1 experiments per request |
/// | `current_dir` | the caller's | a folder |
/// | `protocol` | 1 | 1, or 2 (noise-free runs and given inputs) |
///
/// ```no_run
/// use twostage_models::{ExternalSimulator, ModelSpec, Prior, Simulator, experiment_rng};
/// let spec = ModelSpec::new("sir", &["beta", "gamma"], Prior::uniform_box(&[0.1, 0.05], &[1.0, 0.3])?, 1.0, 10)?
///     .with_signals(&[], &["I"]);
/// let sir = ExternalSimulator::new(spec, vec!["python3".into(), "sir.py".into()])?;
/// let mut record = sir.spec().new_record();
/// sir.simulate(&[0.4, 0.1], &mut experiment_rng(1, 0), &mut record)?;
/// # Ok::<(), twostage_models::SimError>(())
/// ```
#[derive(Debug)]
pub struct ExternalSimulator {
    spec: ModelSpec,
    command: Vec<String>,
    current_dir: Option<PathBuf>,
    timeout: Duration,
    batch: usize,
    protocol: u32,
    idle: Mutex<Vec<Process>>,
}

impl ExternalSimulator {
    /// The program `command[0]` with arguments `command[1..]`, simulating
    /// the model `spec` describes.
    ///
    /// # Errors
    /// [`SimError::InvalidSetting`] for an empty command.
    pub fn new(spec: ModelSpec, command: Vec<String>) -> Result<Self> {
        if command.first().is_none_or(|c| c.trim().is_empty()) {
            return Err(SimError::InvalidSetting(InvalidSetting {
                name: "command",
                value: format!("{command:?}"),
                reason: "give the program and its arguments, e.g. [\"python3\", \"sim.py\"]".into(),
            }));
        }
        Ok(Self {
            spec,
            command,
            current_dir: None,
            timeout: Duration::from_secs(60),
            batch: 1,
            protocol: 1,
            idle: Mutex::new(Vec::new()),
        })
    }

    /// Run the program in `dir` (a model file's folder, say).
    pub fn current_dir(mut self, dir: impl Into<PathBuf>) -> Self {
        self.current_dir = Some(dir.into());
        self
    }

    /// The longest wait for the greeting and for each record.
    pub fn timeout(mut self, timeout: Duration) -> Self {
        self.timeout = timeout;
        self
    }

    /// Experiments per request (at least 1): more for a program that
    /// vectorizes over a batch.
    pub fn batch(mut self, batch: usize) -> Self {
        self.batch = batch.max(1);
        self
    }

    /// Speak protocol `version` (1 or 2): version 2 adds noise-free runs
    /// and given inputs to each request (docs/protocol.md).
    ///
    /// # Errors
    /// [`SimError::InvalidSetting`] for another version.
    pub fn protocol(mut self, version: u32) -> Result<Self> {
        if !(1..=PROTOCOL_VERSION).contains(&version) {
            return Err(SimError::InvalidSetting(InvalidSetting {
                name: "protocol",
                value: version.to_string(),
                reason: format!("this build speaks versions 1 to {PROTOCOL_VERSION}"),
            }));
        }
        self.protocol = version;
        Ok(self)
    }

    /// The command, as one line for messages.
    fn command_line(&self) -> String {
        self.command.join(" ")
    }

    /// Simulate a batch in one request. Each job gets its own result, in
    /// order: a process that fails mid-batch fails the rest of the batch,
    /// and the next request starts a fresh one.
    pub fn simulate_batch(&self, jobs: &[ExternalJob<'_>], outs: &mut [IoData]) -> Vec<Result<()>> {
        self.simulate_jobs(jobs, Conditions::default(), outs)
    }

    /// As [`ExternalSimulator::simulate_batch`], under `conditions`
    /// (protocol 2 for anything but a plain experiment).
    pub fn simulate_jobs(
        &self,
        jobs: &[ExternalJob<'_>],
        conditions: Conditions<'_>,
        outs: &mut [IoData],
    ) -> Vec<Result<()>> {
        let refused = self
            .capabilities()
            .check(&conditions, self.spec.name())
            .and_then(|()| conditions.check_input(&self.spec));
        if let Err(e) = refused {
            return jobs.iter().map(|_| Err(e.clone())).collect();
        }
        let inputs = match self.given_input(conditions) {
            Some(given) => Inputs::Shared(given),
            None => Inputs::Own,
        };
        self.send_jobs(jobs, conditions.noiseless, inputs, outs)
    }

    /// As [`ExternalSimulator::simulate_jobs`], each job on its own given
    /// input (`inputs[k]` for `jobs[k]`, all of one length): one request
    /// whose input mode is `each` (protocol 2).
    pub fn simulate_jobs_on_inputs(
        &self,
        jobs: &[ExternalJob<'_>],
        inputs: &[IoData],
        conditions: Conditions<'_>,
        outs: &mut [IoData],
    ) -> Vec<Result<()>> {
        let refused = (|| {
            if let Some(e) = crate::simulator::inputs_refused(jobs.len(), inputs, conditions) {
                return Err(e);
            }
            let mut length = None;
            for input in inputs {
                let conditions = Conditions {
                    input: Some(input),
                    ..conditions
                };
                self.capabilities().check(&conditions, self.spec.name())?;
                let n = conditions.check_input(&self.spec)?;
                if length.is_some_and(|first| first != n) {
                    return Err(SimError::InvalidData(format!(
                        "the inputs of one request have {} and {n} samples: a request's \
                         records share one length",
                        length.unwrap_or_default()
                    )));
                }
                length = Some(n);
            }
            Ok(())
        })();
        if let Err(e) = refused {
            return jobs.iter().map(|_| Err(e.clone())).collect();
        }
        let inputs = if self.spec.input_names().is_empty() {
            Inputs::Own
        } else {
            Inputs::Each(inputs)
        };
        self.send_jobs(jobs, conditions.noiseless, inputs, outs)
    }

    /// Send the jobs whose parameters the model takes, in one request;
    /// a refused parameter vector is its own job's error.
    fn send_jobs(
        &self,
        jobs: &[ExternalJob<'_>],
        noiseless: bool,
        inputs: Inputs<'_>,
        outs: &mut [IoData],
    ) -> Vec<Result<()>> {
        if jobs.len() != outs.len() {
            let e =
                SimError::InvalidData(format!("{} jobs for {} records", jobs.len(), outs.len()));
            return jobs.iter().map(|_| Err(e.clone())).collect();
        }
        let mut results: Vec<Option<Result<()>>> = jobs
            .iter()
            .map(|job| check_theta(&self.spec, job.theta).err().map(Err))
            .collect();
        let sent: Vec<usize> = (0..jobs.len()).filter(|&i| results[i].is_none()).collect();
        if !sent.is_empty() {
            let batch: Vec<ExternalJob<'_>> = sent.iter().map(|&i| jobs[i]).collect();
            let batch_inputs: Vec<&IoData>;
            let request = Request {
                noiseless,
                inputs: match inputs {
                    Inputs::Each(all) => {
                        batch_inputs = sent.iter().map(|&i| &all[i]).collect();
                        Inputs::EachOf(&batch_inputs)
                    }
                    other => other,
                },
            };
            let mut records: Vec<IoData> =
                sent.iter().map(|&i| std::mem::take(&mut outs[i])).collect();
            let answers = self.request(&batch, request, &mut records);
            for ((&i, record), answer) in sent.iter().zip(records).zip(answers) {
                outs[i] = record;
                results[i] = Some(answer);
            }
        }
        results
            .into_iter()
            .map(|r| r.unwrap_or_else(|| Err(self.failure("no answer"))))
            .collect()
    }

    /// One request to a process of the pool, one result per job.
    fn request(
        &self,
        jobs: &[ExternalJob<'_>],
        request: Request<'_>,
        outs: &mut [IoData],
    ) -> Vec<Result<()>> {
        let mut process = match self.checkout() {
            Ok(p) => p,
            Err(e) => return jobs.iter().map(|_| Err(e.clone())).collect(),
        };
        let mut results = Vec::with_capacity(jobs.len());
        match self.exchange(&mut process, jobs, request, outs, &mut results) {
            Ok(()) => self.checkin(process),
            Err(e) => {
                let e = self.with_stderr(e, &process);
                process.kill();
                while results.len() < jobs.len() {
                    results.push(Err(e.clone()));
                }
            }
        }
        results
    }

    /// Send one request and read its answers into `outs`, pushing one
    /// result per job; an `Err` means the process is out of protocol.
    fn exchange(
        &self,
        process: &mut Process,
        jobs: &[ExternalJob<'_>],
        request: Request<'_>,
        outs: &mut [IoData],
        results: &mut Vec<Result<()>>,
    ) -> Result<()> {
        process
            .send(&self.request_text(jobs, request))
            .map_err(|e| self.failure(&e))?;
        let (n, n_u, n_y) = (
            self.samples(request),
            self.spec.input_names().len(),
            self.spec.output_names().len(),
        );
        for (k_job, (job, out)) in jobs.iter().zip(outs.iter_mut()).enumerate() {
            // The timeout is the whole record's, not each line's: a
            // simulator that trickles its lines is ended all the same.
            let deadline = Instant::now() + self.timeout;
            out.resize(n, n_u, n_y);
            let mut next_line = || process.line_by(deadline, self.timeout);
            match Self::read_answer(&mut next_line, job.index, out) {
                Ok(ProtocolAnswer::Record) => {
                    results.push(self.given_input_kept(job.index, request.inputs.of(k_job), out));
                }
                Ok(ProtocolAnswer::Failed(message)) => results.push(Err(SimError::External {
                    command: self.command_line(),
                    message: format!("experiment {} failed: {message}", job.index),
                })),
                Err(message) => return Err(self.failure(&message)),
            }
        }
        Ok(())
    }

    /// Read one experiment's answer (docs/protocol.md): `record INDEX` and
    /// one line per sample of `out`'s length, its inputs' then its
    /// outputs' values, into `out`; or `error INDEX MESSAGE`. Each line
    /// comes from `next_line`, whose error (a timeout, an ended process)
    /// is passed on with the sample it stopped at.
    ///
    /// ```
    /// use twostage_models::{ExternalSimulator, IoData, ProtocolAnswer};
    /// let mut lines = ["record 4", "0.5 1.0", "-0.5 2.0"].map(String::from).into_iter();
    /// let mut next = || lines.next().ok_or_else(|| "it ended".to_string());
    /// let mut out = IoData::zeros(2, 1, 1);
    /// let answer = ExternalSimulator::read_answer(&mut next, 4, &mut out);
    /// assert_eq!(answer, Ok(ProtocolAnswer::Record));
    /// assert_eq!(out.output(0), &[1.0, 2.0]);
    /// ```
    ///
    /// # Errors
    /// Out of protocol, each message quoting the line: another index, a
    /// value that is not a finite number, a line of another width, or
    /// what `next_line` said.
    pub fn read_answer(
        next_line: &mut dyn FnMut() -> std::result::Result<String, String>,
        index: u64,
        out: &mut IoData,
    ) -> std::result::Result<ProtocolAnswer, String> {
        let (n, n_u, n_y) = (out.n_samples(), out.n_inputs(), out.n_outputs());
        let head = next_line()?;
        let mut words = head.split_whitespace();
        match (words.next(), words.next().map(str::parse::<u64>)) {
            (Some("record"), Some(Ok(i))) if i == index => {}
            (Some("error"), Some(Ok(i))) if i == index => {
                let message = head.splitn(3, ' ').nth(2).unwrap_or("").trim();
                return Ok(ProtocolAnswer::Failed(message.to_string()));
            }
            _ => {
                return Err(format!(
                    "expected `record {index}` or `error {index} MESSAGE`, it answered {head:?}"
                ));
            }
        }
        for k in 0..n {
            let line =
                next_line().map_err(|e| format!("{e} (at sample {k} of experiment {index})"))?;
            let mut count = 0;
            for (c, word) in line.split_whitespace().enumerate() {
                let value: f64 = word.parse().ok().filter(|v: &f64| v.is_finite()).ok_or_else(|| {
                    format!(
                        "sample {k} of experiment {index}: {word:?} is not a finite number (line {line:?})"
                    )
                })?;
                if c < n_u {
                    out.input_mut(c)[k] = value;
                } else if c < n_u + n_y {
                    out.output_mut(c - n_u)[k] = value;
                }
                count += 1;
            }
            if count != n_u + n_y {
                return Err(format!(
                    "sample {k} of experiment {index} has {count} values, the model has {n_u} \
                     input(s) and {n_y} output(s) (line {line:?})"
                ));
            }
        }
        Ok(ProtocolAnswer::Record)
    }

    /// The samples of each record of a request: a given record's length,
    /// else the model's.
    fn samples(&self, request: Request<'_>) -> usize {
        request
            .inputs
            .of(0)
            .map_or(self.spec.n_samples(), IoData::n_samples)
    }

    /// The request's text: `batch B` (version 1), or `batch B NOISE
    /// INPUT` (version 2) then, for a `given` input, its N lines after
    /// the experiments' lines, or, for `each`, every experiment's line
    /// followed by its own input's N lines; a record of another length
    /// than the greeting's N adds it, `batch B NOISE INPUT N2`, and the
    /// records answer with N2 samples.
    fn request_text(&self, jobs: &[ExternalJob<'_>], request: Request<'_>) -> String {
        let mut text = format!("batch {}", jobs.len());
        if self.protocol >= 2 {
            let noise = if request.noiseless {
                "noiseless"
            } else {
                "noise"
            };
            let input = match request.inputs {
                Inputs::Own => "own",
                Inputs::Shared(_) => "given",
                Inputs::Each(_) | Inputs::EachOf(_) => "each",
            };
            let _ = write!(text, " {noise} {input}");
            let samples = self.samples(request);
            if samples != self.spec.n_samples() {
                let _ = write!(text, " {samples}");
            }
        }
        text.push('\n');
        let each = matches!(request.inputs, Inputs::Each(_) | Inputs::EachOf(_));
        for (k, job) in jobs.iter().enumerate() {
            let _ = write!(text, "{} {}", job.index, job.seed);
            for t in job.theta {
                let _ = write!(text, " {t:?}");
            }
            text.push('\n');
            if let (true, Some(input)) = (each, request.inputs.of(k)) {
                input_lines(&mut text, input);
            }
        }
        if let Inputs::Shared(given) = request.inputs {
            input_lines(&mut text, given);
        }
        text
    }

    /// The input to send: none for a model without inputs.
    fn given_input<'c>(&self, conditions: Conditions<'c>) -> Option<&'c IoData> {
        conditions
            .input
            .filter(|_| !self.spec.input_names().is_empty())
    }

    /// A record must carry the input it was given: a simulator that
    /// ignored it would pass off a response to another input.
    fn given_input_kept(&self, index: u64, given: Option<&IoData>, out: &IoData) -> Result<()> {
        let Some(given) = given else {
            return Ok(());
        };
        for j in 0..given.n_inputs() {
            let (sent, back) = (given.input(j), out.input(j));
            if let Some(k) = (0..sent.len()).find(|&k| sent[k].to_bits() != back[k].to_bits()) {
                return Err(self.failure(&format!(
                    "experiment {index} returned input {} = {:?} at sample {k} where it was \
                     given {:?}: a request with a given input must simulate (and return) that \
                     input",
                    self.spec.input_names()[j],
                    back[k],
                    sent[k]
                )));
            }
        }
        Ok(())
    }

    fn failure(&self, message: &str) -> SimError {
        SimError::External {
            command: self.command_line(),
            message: message.to_string(),
        }
    }

    /// The error with the last lines the process wrote to standard error.
    fn with_stderr(&self, e: SimError, process: &Process) -> SimError {
        let tail = process.stderr_tail();
        match e {
            SimError::External { command, message } if !tail.is_empty() => SimError::External {
                command,
                message: format!("{message}; its standard error ended with: {tail}"),
            },
            other => other,
        }
    }

    fn checkout(&self) -> Result<Process> {
        let idle = self
            .idle
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .pop();
        match idle {
            Some(p) => Ok(p),
            None => self.spawn(),
        }
    }

    fn checkin(&self, process: Process) {
        self.idle
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .push(process);
    }

    /// Start the program and exchange the greeting.
    fn spawn(&self) -> Result<Process> {
        let mut command = Command::new(&self.command[0]);
        command
            .args(&self.command[1..])
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped());
        if let Some(dir) = &self.current_dir {
            command.current_dir(dir);
        }
        let mut child = command.spawn().map_err(|e| {
            self.failure(&format!(
                "cannot start it ({e}){}",
                self.current_dir
                    .as_ref()
                    .map_or(String::new(), |d| format!(" in {}", d.display()))
            ))
        })?;
        let (stdin, stdout, stderr) =
            match (child.stdin.take(), child.stdout.take(), child.stderr.take()) {
                (Some(i), Some(o), Some(e)) => (i, o, e),
                _ => {
                    let _ = child.kill();
                    return Err(self.failure("its standard streams could not be opened"));
                }
            };
        let signals = self.spec.input_names().len() + self.spec.output_names().len();
        let mut process = Process::attach(child, stdin, stdout, stderr, signals);
        let spec = &self.spec;
        let greeting = format!(
            "twostage {} {} {} {} {}\n",
            self.protocol,
            spec.n_params(),
            spec.input_names().len(),
            spec.output_names().len(),
            spec.n_samples()
        );
        let answer = process
            .send(&greeting)
            .and_then(|()| process.line(self.timeout));
        match answer {
            Ok(line) if line.trim() == "ready" => Ok(process),
            Ok(line) => {
                let e = self.failure(&format!(
                    "it answered the greeting {:?} with {line:?}, not `ready`",
                    greeting.trim_end()
                ));
                let e = self.with_stderr(e, &process);
                process.kill();
                Err(e)
            }
            Err(message) => {
                // Give a crashing program a moment to write why.
                std::thread::sleep(Duration::from_millis(50));
                let e = self.with_stderr(
                    self.failure(&format!("at the greeting: {message}")),
                    &process,
                );
                process.kill();
                Err(e)
            }
        }
    }
}

impl Simulator for ExternalSimulator {
    fn spec(&self) -> &ModelSpec {
        &self.spec
    }

    fn batch_size(&self) -> usize {
        self.batch
    }

    /// Noise-free runs and given inputs with protocol 2.
    fn capabilities(&self) -> Capabilities {
        let v2 = self.protocol >= 2;
        Capabilities {
            noiseless: v2,
            given_input: v2,
        }
    }

    /// One experiment as a block of one.
    fn simulate_one(
        &self,
        theta: &[f64],
        rng: &mut ExperimentRng,
        conditions: Conditions<'_>,
        out: &mut IoData,
    ) -> Result<()> {
        self.simulate_block(
            &[theta],
            std::slice::from_mut(rng),
            Block::of(conditions),
            std::slice::from_mut(out),
        )
        .pop()
        .unwrap_or_else(|| Err(self.failure("no answer")))
    }

    /// One request for the block; each experiment's index and seed come
    /// from its stream ([`ExternalJob::stream_of`]), its input after its
    /// line when each has its own (`each`, protocol 2).
    fn simulate_block(
        &self,
        thetas: &[&[f64]],
        rngs: &mut [ExperimentRng],
        block: Block<'_>,
        outs: &mut [IoData],
    ) -> Vec<Result<()>> {
        let jobs = jobs_of(thetas, rngs);
        match block.inputs {
            BlockInputs::Each(inputs) => {
                let conditions = Conditions {
                    noiseless: block.noiseless,
                    input: None,
                };
                self.simulate_jobs_on_inputs(&jobs, inputs, conditions, outs)
            }
            _ => self.simulate_jobs(&jobs, block.conditions(0), outs),
        }
    }
}

/// What a request asks of its records beside the parameters.
#[derive(Clone, Copy)]
struct Request<'a> {
    noiseless: bool,
    inputs: Inputs<'a>,
}

/// The inputs of a request's experiments.
#[derive(Clone, Copy)]
enum Inputs<'a> {
    /// The simulator's own design.
    Own,
    /// One given input for every experiment (`given`).
    Shared(&'a IoData),
    /// Each experiment's own (`each`), as the caller handed them.
    Each(&'a [IoData]),
    /// Each experiment's own, of the experiments sent.
    EachOf(&'a [&'a IoData]),
}

impl<'a> Inputs<'a> {
    /// The input the request's `k`-th experiment is given, if any.
    fn of(self, k: usize) -> Option<&'a IoData> {
        match self {
            Inputs::Own => None,
            Inputs::Shared(input) => Some(input),
            Inputs::Each(all) => all.get(k),
            Inputs::EachOf(all) => all.get(k).copied(),
        }
    }
}

/// Append an input's samples, one line of its signals per sample, each
/// value written to read back to the same bits.
fn input_lines(text: &mut String, input: &IoData) {
    for k in 0..input.n_samples() {
        for j in 0..input.n_inputs() {
            if j > 0 {
                text.push(' ');
            }
            let _ = write!(text, "{:?}", input.input(j)[k]);
        }
        text.push('\n');
    }
}

/// Each experiment's job: its parameters, and the index and seed its
/// stream stands for.
fn jobs_of<'t>(thetas: &[&'t [f64]], rngs: &[ExperimentRng]) -> Vec<ExternalJob<'t>> {
    thetas
        .iter()
        .zip(rngs)
        .map(|(theta, rng)| {
            let (index, seed) = ExternalJob::stream_of(rng);
            ExternalJob { index, seed, theta }
        })
        .collect()
}

impl Drop for ExternalSimulator {
    fn drop(&mut self) {
        let idle = std::mem::take(self.idle.get_mut().unwrap_or_else(PoisonError::into_inner));
        for mut process in idle {
            // A polite end first: `quit`, then the process has a moment to go.
            let _ = process.send("quit\n");
            let deadline = Instant::now() + Duration::from_millis(200);
            while Instant::now() < deadline {
                if matches!(process.child.try_wait(), Ok(Some(_))) {
                    break;
                }
                std::thread::sleep(Duration::from_millis(5));
            }
            process.kill();
        }
    }
}
