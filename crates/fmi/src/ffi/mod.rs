//! The FMI C API, loaded from an FMU's binary, behind safe methods.
//!
//! With the C API of crates/runtime-c, this is the project's unsafe code
//! (docs/decisions/022-fmus.md): the function pointers are read from the
//! shared library once, checked to be there, and every call goes through a
//! [`Component`] that owns a live instance. Each FMI version's functions
//! are one table ([`fmi2`], [`fmi3`]) behind one [`api::Api`], so a
//! component's method is one call whatever the version. The signatures
//! are those of the standards' headers (`fmi2FunctionTypes.h`, FMI 2.0.4
//! section 2.1; `fmi3FunctionTypes.h`, FMI 3.0.1 section 2.3), written
//! here from the documents.
#![allow(unsafe_code)]

mod api;
mod fmi2;
mod fmi3;
mod log;

use std::ffi::{CString, c_void};
use std::path::Path;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

use libloading::Library;

use crate::description::{FmiVersion, InterfaceKind};
use crate::error::{FmiError, Result};
use api::{Api, Call, Handle, Unsupported};
use log::{Log, status_word};

/// An error and every cause under it, as one line: the loader's own reason
/// ("undefined symbol: ...") is a cause of libloading's "dlopen failed".
fn chain(error: &dyn std::error::Error) -> String {
    let mut text = error.to_string();
    let mut cause = error.source();
    while let Some(inner) = cause {
        let more = inner.to_string();
        if !text.contains(&more) {
            text = format!("{text}: {more}");
        }
        cause = inner.source();
    }
    text
}

/// The named functions of a library, each required by the standard.
struct Symbols<'l> {
    library: &'l Library,
    origin: &'l str,
    binary: &'l Path,
}

impl Symbols<'_> {
    /// The function `name`, or an error saying the binary lacks it.
    fn required<T: Copy>(&self, name: &str) -> Result<T> {
        // SAFETY: the type comes from the standard's signature for `name`.
        unsafe { self.library.get::<T>(name.as_bytes()) }
            .ok()
            .map(|s| *s)
            .ok_or_else(|| FmiError::Binary {
                path: self.origin.into(),
                binary: self.binary.display().to_string(),
                message: format!("does not export {name}, which the standard requires"),
            })
    }
}

/// A loaded FMU binary: its functions, for one interface.
pub(crate) struct Binary {
    api: Box<dyn Api>,
    /// After a fatal status no function of any instance may be called
    /// again (FMI 2.0 section 2.1.3, FMI 3.0 section 2.2.3).
    fatal: AtomicBool,
    origin: String,
    token: CString,
    resources: CString,
    // Dropped last: the function pointers above point into it.
    _library: Library,
}

impl Binary {
    /// Load the shared library and its functions for `kind` (and FMI 2.0's
    /// input derivatives if `interpolate_inputs`).
    pub fn load(
        path: &Path,
        version: FmiVersion,
        kind: InterfaceKind,
        interpolate_inputs: bool,
        origin: &str,
        token: &str,
        resources: &str,
    ) -> Result<Self> {
        let fail = |message: String| FmiError::Binary {
            path: origin.into(),
            binary: path.display().to_string(),
            message,
        };
        // SAFETY: loading runs the library's initializers; an FMU binary is
        // code the user chose to run, as a simulator is.
        let library = unsafe { Library::new(path) }
            .map_err(|e| fail(format!("cannot be loaded: {}", chain(&e))))?;
        let api: Box<dyn Api> = match version {
            FmiVersion::V2 => Box::new(fmi2::Fmi2::load(
                &library,
                kind,
                interpolate_inputs,
                origin,
                path,
            )?),
            FmiVersion::V3 => Box::new(fmi3::Fmi3::load(&library, kind, origin, path)?),
        };
        let c_string = |what: &str, s: &str| {
            CString::new(s).map_err(|_| fail(format!("{what} holds a NUL byte")))
        };
        Ok(Self {
            api,
            fatal: AtomicBool::new(false),
            origin: origin.into(),
            token: c_string("the instantiation token", token)?,
            resources: c_string("the resource path", resources)?,
            _library: library,
        })
    }

    /// A new instance, named `name`.
    pub fn instantiate(self: &Arc<Self>, name: &str) -> Result<Component> {
        self.refuse_after_fatal("instantiate", 0.0)?;
        let log = Box::new(Log::default());
        let environment = &*log as *const Log as *mut c_void;
        let instance_name = CString::new(name).map_err(|_| FmiError::Setting {
            name: "instance name",
            value: name.into(),
            reason: "must not hold a NUL byte".into(),
        })?;
        // SAFETY: every pointer passed lives as long as the instance: the
        // strings are owned by `self`, the log and the callbacks by the
        // component returned.
        let instance = unsafe {
            self.api
                .instantiate(&instance_name, &self.token, &self.resources, environment)
        };
        if instance.handle.is_null() {
            return Err(FmiError::Call {
                path: self.origin.clone(),
                function: "instantiate",
                time: 0.0,
                status: "no instance (a null pointer)".into(),
                log: log.take(),
            });
        }
        Ok(Component {
            binary: Arc::clone(self),
            handle: instance.handle,
            log,
            _keep: instance.keep,
            time: 0.0,
        })
    }

    /// Whether a call returned Fatal: no function may be called again.
    pub fn is_fatal(&self) -> bool {
        self.fatal.load(Ordering::Acquire)
    }

    fn refuse_after_fatal(&self, function: &'static str, time: f64) -> Result<()> {
        if self.fatal.load(Ordering::Acquire) {
            return Err(FmiError::Call {
                path: self.origin.clone(),
                function,
                time,
                status: "not called: an earlier call returned Fatal, after which the \
                         standard forbids every call to the FMU"
                    .into(),
                log: Vec::new(),
            });
        }
        Ok(())
    }
}

/// What an event iteration found (FMI 2.0 `fmi2EventInfo`, FMI 3.0
/// `fmi3UpdateDiscreteStates`).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub(crate) struct EventUpdate {
    pub terminate: bool,
    pub states_changed: bool,
    pub next_event_time: Option<f64>,
}

/// One live instance of an FMU.
pub(crate) struct Component {
    binary: Arc<Binary>,
    handle: Handle,
    log: Box<Log>,
    /// What the instance's version needs kept alive beside it (FMI 2.0's
    /// callback table).
    _keep: Option<Box<dyn std::any::Any + Send>>,
    /// The simulation time of the last call, for messages.
    time: f64,
}

// SAFETY: an instance may move between threads; `&mut self` on every call
// keeps two threads from using it at once. The function table is
// immutable after loading, and FMI allows calls from any thread as long as
// one instance is not used by two threads at once.
unsafe impl Send for Component {}

impl Drop for Component {
    fn drop(&mut self) {
        if self.binary.is_fatal() {
            return;
        }
        // SAFETY: the handle is live and is freed once, here.
        unsafe { self.binary.api.free_instance(self.handle) }
    }
}

impl Component {
    /// Turn a call's status into a result, quoting the log on failure.
    fn check(&self, call: Call) -> Result<()> {
        match call.status {
            0 | 1 => Ok(()),
            status => {
                if status == 4 {
                    self.binary.fatal.store(true, Ordering::Release);
                }
                Err(FmiError::Call {
                    path: self.binary.origin.clone(),
                    function: call.function,
                    time: self.time,
                    status: status_word(status).into(),
                    log: self.log.take(),
                })
            }
        }
    }

    fn refused(&self, function: &'static str, message: String) -> FmiError {
        FmiError::Call {
            path: self.binary.origin.clone(),
            function,
            time: self.time,
            status: message,
            log: self.log.take(),
        }
    }

    /// A call this instance's interface has, checked; or why it has none.
    fn checked(&self, call: std::result::Result<Call, Unsupported>) -> Result<()> {
        match call {
            Ok(call) => self.check(call),
            Err((function, why)) => Err(self.refused(function, why.into())),
        }
    }

    /// Back to the state right after instantiation, for the next experiment.
    pub fn reset(&mut self) -> Result<()> {
        self.binary.refuse_after_fatal("reset", self.time)?;
        self.log.clear();
        self.time = 0.0;
        // SAFETY: a live handle.
        let call = unsafe { self.binary.api.reset(self.handle) };
        self.check(Call {
            function: "reset",
            ..call
        })
    }

    /// Set real variables.
    pub fn set_reals(&mut self, references: &[u32], values: &[f64]) -> Result<()> {
        debug_assert_eq!(references.len(), values.len());
        if references.is_empty() {
            return Ok(());
        }
        self.binary.refuse_after_fatal("set", self.time)?;
        // SAFETY: both slices hold `len` elements.
        let call = unsafe { self.binary.api.set_reals(self.handle, references, values) };
        self.check(call)
    }

    /// Read real variables.
    pub fn get_reals(&mut self, references: &[u32], values: &mut [f64]) -> Result<()> {
        debug_assert_eq!(references.len(), values.len());
        if references.is_empty() {
            return Ok(());
        }
        self.binary.refuse_after_fatal("get", self.time)?;
        // SAFETY: both slices hold `len` elements.
        let call = unsafe { self.binary.api.get_reals(self.handle, references, values) };
        self.check(call)
    }

    /// FMI 2.0 co-simulation: the first derivatives of inputs over the
    /// coming communication step.
    pub fn set_input_slopes(&mut self, references: &[u32], slopes: &[f64]) -> Result<()> {
        debug_assert_eq!(references.len(), slopes.len());
        // SAFETY: both slices hold `len` elements.
        let call = unsafe {
            self.binary
                .api
                .set_input_slopes(self.handle, references, slopes)
        };
        self.checked(call)
    }

    /// Enter and leave initialization mode at `start_time` (after the start
    /// values are set). A co-simulation FMU is then ready to step; a
    /// model-exchange FMU is in event mode, and [`Component::update_discrete`]
    /// comes next.
    pub fn initialize(&mut self, start_time: f64) -> Result<()> {
        self.binary.refuse_after_fatal("initialize", start_time)?;
        self.time = start_time;
        let this = &*self;
        // SAFETY: a live handle.
        unsafe {
            this.binary
                .api
                .initialize(this.handle, start_time, &mut |call| this.check(call))
        }
    }

    /// Co-simulation: advance from `time` by `step`.
    pub fn do_step(&mut self, time: f64, step: f64) -> Result<()> {
        self.binary.refuse_after_fatal("doStep", time)?;
        self.time = time;
        // SAFETY: a live handle.
        match unsafe { self.binary.api.do_step(self.handle, time, step) } {
            Err((function, why)) => Err(self.refused(function, why.into())),
            Ok((call, end)) => {
                self.check(call)?;
                match end.terminate_at {
                    Some(reached) => Err(self.refused(
                        call.function,
                        format!("a request to terminate the simulation (reached t = {reached})"),
                    )),
                    None => Ok(()),
                }
            }
        }
    }

    /// Model exchange: the time.
    pub fn set_time(&mut self, time: f64) -> Result<()> {
        self.time = time;
        // SAFETY: a live handle.
        let call = unsafe { self.binary.api.set_time(self.handle, time) };
        self.checked(call)
    }

    /// Model exchange: set the continuous states.
    pub fn set_states(&mut self, x: &[f64]) -> Result<()> {
        // SAFETY: a live handle; `x` holds `len` values.
        let call = unsafe { self.binary.api.set_states(self.handle, x) };
        self.checked(call)
    }

    /// Model exchange: read the continuous states.
    pub fn get_states(&mut self, x: &mut [f64]) -> Result<()> {
        // SAFETY: a live handle; `x` holds `len` values.
        let call = unsafe { self.binary.api.get_states(self.handle, x) };
        self.checked(call)
    }

    /// Model exchange: the state derivatives at the current time, states
    /// and inputs.
    pub fn derivatives(&mut self, dx: &mut [f64]) -> Result<()> {
        // SAFETY: a live handle; `dx` holds `len` values.
        let call = unsafe { self.binary.api.derivatives(self.handle, dx) };
        self.checked(call)
    }

    /// Model exchange: enter event mode (from continuous-time mode).
    pub fn enter_event_mode(&mut self) -> Result<()> {
        // SAFETY: a live handle.
        let call = unsafe { self.binary.api.enter_event_mode(self.handle) };
        self.checked(call)
    }

    /// Model exchange, in event mode: iterate the discrete states until
    /// they settle, then enter continuous-time mode.
    pub fn update_discrete(&mut self) -> Result<EventUpdate> {
        let mut update = EventUpdate::default();
        // The standard leaves the number of iterations to the FMU; an FMU
        // that never settles is broken, and is told so.
        for _ in 0..1000 {
            // SAFETY: a live handle.
            let (call, found) = match unsafe { self.binary.api.update_discrete(self.handle) } {
                Ok(outcome) => outcome,
                Err((function, why)) => return Err(self.refused(function, why.into())),
            };
            update.terminate |= found.terminate;
            update.states_changed |= found.states_changed;
            update.next_event_time = found.next_event_time;
            self.check(call)?;
            if update.terminate {
                return Err(self.refused(
                    call.function,
                    "a request to terminate the simulation".into(),
                ));
            }
            if !found.again {
                // SAFETY: a live handle.
                let call = unsafe { self.binary.api.enter_continuous_time_mode(self.handle) };
                self.checked(call)?;
                return Ok(update);
            }
        }
        Err(self.refused(
            "event iteration",
            "the discrete states did not settle in 1000 iterations".into(),
        ))
    }

    /// Model exchange: tell the FMU an integrator step is complete;
    /// `true` if it asks for event mode (a step event).
    pub fn completed_step(&mut self) -> Result<bool> {
        // SAFETY: a live handle.
        let (call, event, terminate) = match unsafe { self.binary.api.completed_step(self.handle) }
        {
            Ok(outcome) => outcome,
            Err((function, why)) => return Err(self.refused(function, why.into())),
        };
        self.check(call)?;
        if terminate {
            return Err(self.refused(
                call.function,
                "a request to terminate the simulation".into(),
            ));
        }
        Ok(event)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::ffi::c_int;

    #[test]
    fn status_words_follow_the_standard_order() {
        let words: Vec<&str> = (0..6 as c_int).map(status_word).collect();
        assert_eq!(
            words,
            ["OK", "Warning", "Discard", "Error", "Fatal", "Pending"]
        );
        assert_eq!(status_word(9), "unknown status");
    }
}
