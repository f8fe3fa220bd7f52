//! The FMI C API, loaded from an FMU's binary, behind safe methods.
//!
//! This is the crate's only unsafe code (docs/decisions/022-fmus.md): the
//! function pointers are read from the shared library once, checked to be
//! there, and every call goes through a [`Component`] that owns a live
//! instance. The signatures are those of the standards' headers
//! (`fmi2FunctionTypes.h`, FMI 2.0.4 section 2.1; `fmi3FunctionTypes.h`,
//! FMI 3.0.1 section 2.3), written here from the documents.
#![allow(unsafe_code)]

use std::collections::VecDeque;
use std::ffi::{CStr, CString, c_char, c_int, c_void};
use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Mutex, PoisonError};

use libloading::Library;

use crate::description::{FmiVersion, InterfaceKind};
use crate::error::{FmiError, Result};

type Handle = *mut c_void;

/// How many of an instance's last log messages an error quotes.
const LOG_LINES: usize = 8;

/// The messages an instance logged, the last [`LOG_LINES`] of them.
#[derive(Debug, Default)]
pub(crate) struct Log {
    lines: Mutex<VecDeque<String>>,
}

impl Log {
    fn push(&self, line: String) {
        let mut lines = self.lines.lock().unwrap_or_else(PoisonError::into_inner);
        if lines.len() == LOG_LINES {
            lines.pop_front();
        }
        lines.push_back(line);
    }

    fn take(&self) -> Vec<String> {
        let mut lines = self.lines.lock().unwrap_or_else(PoisonError::into_inner);
        lines.drain(..).collect()
    }

    fn clear(&self) {
        self.lines
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .clear();
    }
}

fn text(pointer: *const c_char) -> String {
    if pointer.is_null() {
        String::new()
    } else {
        // SAFETY: the FMU passes a NUL-terminated string valid for the call.
        unsafe { CStr::from_ptr(pointer) }
            .to_string_lossy()
            .into_owned()
    }
}

/// The sink of every FMU message: FMI 3.0's log callback itself, and the
/// end of FMI 2.0's variadic logger (src/logger.c). `environment` is the
/// instance's [`Log`].
///
/// # Safety
/// `environment` is null or the `Log` an instance was created with, alive;
/// `category` and `message` are null or NUL-terminated strings, as FMI
/// promises of its callers.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn twostage_fmi_log(
    environment: *mut c_void,
    status: c_int,
    category: *const c_char,
    message: *const c_char,
) {
    if environment.is_null() {
        return;
    }
    // SAFETY: every instance is created with its own boxed Log as the
    // environment, and the Log outlives the instance.
    let log = unsafe { &*(environment as *const Log) };
    let category = text(category);
    let message = text(message);
    let message = message.trim_end();
    log.push(if category.is_empty() {
        format!("{}: {message}", status_word(status))
    } else {
        format!("{} [{category}]: {message}", status_word(status))
    });
}

fn status_word(status: c_int) -> &'static str {
    match status {
        0 => "OK",
        1 => "Warning",
        2 => "Discard",
        3 => "Error",
        4 => "Fatal",
        5 => "Pending",
        _ => "unknown status",
    }
}

unsafe extern "C" {
    fn twostage_fmi2_logger(
        environment: *mut c_void,
        instance_name: *const c_char,
        status: c_int,
        category: *const c_char,
        message: *const c_char,
        ...
    );
    fn twostage_fmi2_calloc(count: usize, size: usize) -> *mut c_void;
    fn twostage_fmi2_free(pointer: *mut c_void);
}

/// `fmi2CallbackFunctions`.
#[repr(C)]
struct Fmi2Callbacks {
    logger:
        unsafe extern "C" fn(*mut c_void, *const c_char, c_int, *const c_char, *const c_char, ...),
    allocate_memory: unsafe extern "C" fn(usize, usize) -> *mut c_void,
    free_memory: unsafe extern "C" fn(*mut c_void),
    step_finished: Option<unsafe extern "C" fn(*mut c_void, c_int)>,
    component_environment: *mut c_void,
}

/// `fmi2EventInfo`.
#[repr(C)]
#[derive(Default)]
struct Fmi2EventInfo {
    new_discrete_states_needed: c_int,
    terminate_simulation: c_int,
    nominals_of_continuous_states_changed: c_int,
    values_of_continuous_states_changed: c_int,
    next_event_time_defined: c_int,
    next_event_time: f64,
}

type Status0 = unsafe extern "C" fn(Handle) -> c_int;
type InputDerivatives =
    unsafe extern "C" fn(Handle, *const u32, usize, *const c_int, *const f64) -> c_int;
type SetReals = unsafe extern "C" fn(Handle, *const u32, usize, *const f64) -> c_int;
type GetReals = unsafe extern "C" fn(Handle, *const u32, usize, *mut f64) -> c_int;
type SetTime = unsafe extern "C" fn(Handle, f64) -> c_int;
type Vector = unsafe extern "C" fn(Handle, *mut f64, usize) -> c_int;
type ConstVector = unsafe extern "C" fn(Handle, *const f64, usize) -> c_int;

struct Fmi2 {
    instantiate: unsafe extern "C" fn(
        *const c_char,
        c_int,
        *const c_char,
        *const c_char,
        *const Fmi2Callbacks,
        c_int,
        c_int,
    ) -> Handle,
    free_instance: unsafe extern "C" fn(Handle),
    setup_experiment: unsafe extern "C" fn(Handle, c_int, f64, f64, c_int, f64) -> c_int,
    enter_initialization_mode: Status0,
    exit_initialization_mode: Status0,
    reset: Status0,
    set_real: SetReals,
    get_real: GetReals,
    do_step: Option<unsafe extern "C" fn(Handle, f64, f64, c_int) -> c_int>,
    set_real_input_derivatives: Option<InputDerivatives>,
    me: Option<Fmi2Me>,
}

struct Fmi2Me {
    set_time: SetTime,
    set_continuous_states: ConstVector,
    get_derivatives: Vector,
    get_continuous_states: Vector,
    enter_event_mode: Status0,
    new_discrete_states: unsafe extern "C" fn(Handle, *mut Fmi2EventInfo) -> c_int,
    enter_continuous_time_mode: Status0,
    completed_integrator_step: unsafe extern "C" fn(Handle, c_int, *mut c_int, *mut c_int) -> c_int,
}

type Fmi3LogMessage = unsafe extern "C" fn(*mut c_void, c_int, *const c_char, *const c_char);
type Fmi3IntermediateUpdate =
    unsafe extern "C" fn(*mut c_void, f64, bool, bool, bool, bool, *mut bool, *mut f64);

type Fmi3InstantiateCoSimulation = unsafe extern "C" fn(
    *const c_char,
    *const c_char,
    *const c_char,
    bool,
    bool,
    bool,
    bool,
    *const u32,
    usize,
    *mut c_void,
    Option<Fmi3LogMessage>,
    Option<Fmi3IntermediateUpdate>,
) -> Handle;
type Fmi3InstantiateModelExchange = unsafe extern "C" fn(
    *const c_char,
    *const c_char,
    *const c_char,
    bool,
    bool,
    *mut c_void,
    Option<Fmi3LogMessage>,
) -> Handle;

struct Fmi3 {
    instantiate_co_simulation: Option<Fmi3InstantiateCoSimulation>,
    instantiate_model_exchange: Option<Fmi3InstantiateModelExchange>,
    free_instance: unsafe extern "C" fn(Handle),
    enter_initialization_mode: unsafe extern "C" fn(Handle, bool, f64, f64, bool, f64) -> c_int,
    exit_initialization_mode: Status0,
    reset: Status0,
    set_float64: unsafe extern "C" fn(Handle, *const u32, usize, *const f64, usize) -> c_int,
    get_float64: unsafe extern "C" fn(Handle, *const u32, usize, *mut f64, usize) -> c_int,
    do_step: Option<
        unsafe extern "C" fn(
            Handle,
            f64,
            f64,
            bool,
            *mut bool,
            *mut bool,
            *mut bool,
            *mut f64,
        ) -> c_int,
    >,
    me: Option<Fmi3Me>,
}

struct Fmi3Me {
    set_time: SetTime,
    set_continuous_states: ConstVector,
    get_derivatives: Vector,
    get_continuous_states: Vector,
    enter_event_mode: Status0,
    update_discrete_states: unsafe extern "C" fn(
        Handle,
        *mut bool,
        *mut bool,
        *mut bool,
        *mut bool,
        *mut bool,
        *mut f64,
    ) -> c_int,
    enter_continuous_time_mode: Status0,
    completed_integrator_step: unsafe extern "C" fn(Handle, bool, *mut bool, *mut bool) -> c_int,
}

enum Functions {
    V2(Fmi2),
    V3(Fmi3),
}

/// A loaded FMU binary: its functions, for one interface.
pub(crate) struct Binary {
    functions: Functions,
    kind: InterfaceKind,
    /// After a fatal status no function of any instance may be called
    /// again (FMI 2.0 section 2.1.3, FMI 3.0 section 2.2.3).
    fatal: AtomicBool,
    origin: String,
    token: CString,
    resources: CString,
    // Dropped last: the function pointers above point into it.
    _library: Library,
}

// SAFETY: the function table is immutable after loading, and FMI allows
// calls from any thread as long as one instance is not used by two threads
// at once, which `Component` (owned, `&mut self`) guarantees.
unsafe impl Send for Binary {}
unsafe impl Sync for Binary {}

/// Read one function; `Ok(None)` if optional and missing.
fn symbol<T: Copy>(library: &Library, name: &str, origin: &str, binary: &Path) -> Result<T> {
    optional(library, name).ok_or_else(|| FmiError::Binary {
        path: origin.into(),
        binary: binary.display().to_string(),
        message: format!("does not export {name}, which the standard requires"),
    })
}

fn optional<T: Copy>(library: &Library, name: &str) -> Option<T> {
    // SAFETY: the type comes from the standard's signature for `name`.
    unsafe { library.get::<T>(name.as_bytes()) }
        .ok()
        .map(|s| *s)
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
        let library =
            unsafe { Library::new(path) }.map_err(|e| fail(format!("cannot be loaded: {e}")))?;
        macro_rules! get {
            ($name:literal) => {
                symbol(&library, $name, origin, path)?
            };
        }
        let functions = match version {
            FmiVersion::V2 => Functions::V2(Fmi2 {
                instantiate: get!("fmi2Instantiate"),
                free_instance: get!("fmi2FreeInstance"),
                setup_experiment: get!("fmi2SetupExperiment"),
                enter_initialization_mode: get!("fmi2EnterInitializationMode"),
                exit_initialization_mode: get!("fmi2ExitInitializationMode"),
                reset: get!("fmi2Reset"),
                set_real: get!("fmi2SetReal"),
                get_real: get!("fmi2GetReal"),
                do_step: match kind {
                    InterfaceKind::CoSimulation => Some(get!("fmi2DoStep")),
                    InterfaceKind::ModelExchange => None,
                },
                set_real_input_derivatives: if interpolate_inputs {
                    Some(get!("fmi2SetRealInputDerivatives"))
                } else {
                    None
                },
                me: match kind {
                    InterfaceKind::CoSimulation => None,
                    InterfaceKind::ModelExchange => Some(Fmi2Me {
                        set_time: get!("fmi2SetTime"),
                        set_continuous_states: get!("fmi2SetContinuousStates"),
                        get_derivatives: get!("fmi2GetDerivatives"),
                        get_continuous_states: get!("fmi2GetContinuousStates"),
                        enter_event_mode: get!("fmi2EnterEventMode"),
                        new_discrete_states: get!("fmi2NewDiscreteStates"),
                        enter_continuous_time_mode: get!("fmi2EnterContinuousTimeMode"),
                        completed_integrator_step: get!("fmi2CompletedIntegratorStep"),
                    }),
                },
            }),
            FmiVersion::V3 => Functions::V3(Fmi3 {
                instantiate_co_simulation: match kind {
                    InterfaceKind::CoSimulation => Some(get!("fmi3InstantiateCoSimulation")),
                    InterfaceKind::ModelExchange => None,
                },
                instantiate_model_exchange: match kind {
                    InterfaceKind::CoSimulation => None,
                    InterfaceKind::ModelExchange => Some(get!("fmi3InstantiateModelExchange")),
                },
                free_instance: get!("fmi3FreeInstance"),
                enter_initialization_mode: get!("fmi3EnterInitializationMode"),
                exit_initialization_mode: get!("fmi3ExitInitializationMode"),
                reset: get!("fmi3Reset"),
                set_float64: get!("fmi3SetFloat64"),
                get_float64: get!("fmi3GetFloat64"),
                do_step: match kind {
                    InterfaceKind::CoSimulation => Some(get!("fmi3DoStep")),
                    InterfaceKind::ModelExchange => None,
                },
                me: match kind {
                    InterfaceKind::CoSimulation => None,
                    InterfaceKind::ModelExchange => Some(Fmi3Me {
                        set_time: get!("fmi3SetTime"),
                        set_continuous_states: get!("fmi3SetContinuousStates"),
                        get_derivatives: get!("fmi3GetContinuousStateDerivatives"),
                        get_continuous_states: get!("fmi3GetContinuousStates"),
                        enter_event_mode: get!("fmi3EnterEventMode"),
                        update_discrete_states: get!("fmi3UpdateDiscreteStates"),
                        enter_continuous_time_mode: get!("fmi3EnterContinuousTimeMode"),
                        completed_integrator_step: get!("fmi3CompletedIntegratorStep"),
                    }),
                },
            }),
        };
        let c_string = |what: &str, s: &str| {
            CString::new(s).map_err(|_| fail(format!("{what} holds a NUL byte")))
        };
        Ok(Self {
            functions,
            kind,
            fatal: AtomicBool::new(false),
            origin: origin.into(),
            token: c_string("the instantiation token", token)?,
            resources: c_string("the resource path", resources)?,
            _library: library,
        })
    }

    /// A new instance, named `name`.
    pub fn instantiate(self: &std::sync::Arc<Self>, name: &str) -> Result<Component> {
        self.refuse_after_fatal("instantiate", 0.0)?;
        let log = Box::new(Log::default());
        let environment = &*log as *const Log as *mut c_void;
        let instance_name = CString::new(name).map_err(|_| FmiError::Setting {
            name: "instance name",
            value: name.into(),
            reason: "must not hold a NUL byte".into(),
        })?;
        let mut callbacks = None;
        // SAFETY: every pointer passed lives as long as the instance: the
        // strings are owned by `self`, the log and the callbacks by the
        // component returned.
        let handle = unsafe {
            match &self.functions {
                Functions::V2(f) => {
                    let table = Box::new(Fmi2Callbacks {
                        logger: twostage_fmi2_logger,
                        allocate_memory: twostage_fmi2_calloc,
                        free_memory: twostage_fmi2_free,
                        step_finished: None,
                        component_environment: environment,
                    });
                    let kind = match self.kind {
                        InterfaceKind::ModelExchange => 0,
                        InterfaceKind::CoSimulation => 1,
                    };
                    let handle = (f.instantiate)(
                        instance_name.as_ptr(),
                        kind,
                        self.token.as_ptr(),
                        self.resources.as_ptr(),
                        &*table,
                        0,
                        1,
                    );
                    callbacks = Some(table);
                    handle
                }
                Functions::V3(f) => {
                    match (f.instantiate_co_simulation, f.instantiate_model_exchange) {
                        (Some(instantiate), _) => instantiate(
                            instance_name.as_ptr(),
                            self.token.as_ptr(),
                            self.resources.as_ptr(),
                            false,
                            true,
                            false,
                            false,
                            std::ptr::null(),
                            0,
                            environment,
                            Some(twostage_fmi_log),
                            None,
                        ),
                        (None, Some(instantiate)) => instantiate(
                            instance_name.as_ptr(),
                            self.token.as_ptr(),
                            self.resources.as_ptr(),
                            false,
                            true,
                            environment,
                            Some(twostage_fmi_log),
                        ),
                        (None, None) => std::ptr::null_mut(),
                    }
                }
            }
        };
        if handle.is_null() {
            return Err(FmiError::Call {
                path: self.origin.clone(),
                function: "instantiate",
                time: 0.0,
                status: "no instance (a null pointer)".into(),
                log: log.take(),
            });
        }
        Ok(Component {
            binary: std::sync::Arc::clone(self),
            handle,
            log,
            _callbacks: callbacks,
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
    binary: std::sync::Arc<Binary>,
    handle: Handle,
    log: Box<Log>,
    _callbacks: Option<Box<Fmi2Callbacks>>,
    /// The simulation time of the last call, for messages.
    time: f64,
}

// SAFETY: an instance may move between threads; `&mut self` on every call
// keeps two threads from using it at once.
unsafe impl Send for Component {}

impl Drop for Component {
    fn drop(&mut self) {
        if self.binary.fatal.load(Ordering::Acquire) {
            return;
        }
        // SAFETY: the handle is live and is freed once, here.
        unsafe {
            match &self.binary.functions {
                Functions::V2(f) => (f.free_instance)(self.handle),
                Functions::V3(f) => (f.free_instance)(self.handle),
            }
        }
    }
}

impl Component {
    /// Turn a status into a result, quoting the log on failure.
    fn check(&self, function: &'static str, status: c_int) -> Result<()> {
        match status {
            0 | 1 => Ok(()),
            _ => {
                if status == 4 {
                    self.binary.fatal.store(true, Ordering::Release);
                }
                Err(FmiError::Call {
                    path: self.binary.origin.clone(),
                    function,
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

    /// Back to the state right after instantiation, for the next experiment.
    pub fn reset(&mut self) -> Result<()> {
        self.binary.refuse_after_fatal("reset", self.time)?;
        self.log.clear();
        self.time = 0.0;
        // SAFETY: a live handle.
        let status = unsafe {
            match &self.binary.functions {
                Functions::V2(f) => (f.reset)(self.handle),
                Functions::V3(f) => (f.reset)(self.handle),
            }
        };
        self.check("reset", status)
    }

    /// Set real variables.
    pub fn set_reals(&mut self, references: &[u32], values: &[f64]) -> Result<()> {
        debug_assert_eq!(references.len(), values.len());
        if references.is_empty() {
            return Ok(());
        }
        self.binary.refuse_after_fatal("set", self.time)?;
        // SAFETY: both slices hold `len` elements.
        let (name, status) = unsafe {
            match &self.binary.functions {
                Functions::V2(f) => (
                    "fmi2SetReal",
                    (f.set_real)(
                        self.handle,
                        references.as_ptr(),
                        references.len(),
                        values.as_ptr(),
                    ),
                ),
                Functions::V3(f) => (
                    "fmi3SetFloat64",
                    (f.set_float64)(
                        self.handle,
                        references.as_ptr(),
                        references.len(),
                        values.as_ptr(),
                        values.len(),
                    ),
                ),
            }
        };
        self.check(name, status)
    }

    /// Read real variables.
    pub fn get_reals(&mut self, references: &[u32], values: &mut [f64]) -> Result<()> {
        debug_assert_eq!(references.len(), values.len());
        if references.is_empty() {
            return Ok(());
        }
        self.binary.refuse_after_fatal("get", self.time)?;
        // SAFETY: both slices hold `len` elements.
        let (name, status) = unsafe {
            match &self.binary.functions {
                Functions::V2(f) => (
                    "fmi2GetReal",
                    (f.get_real)(
                        self.handle,
                        references.as_ptr(),
                        references.len(),
                        values.as_mut_ptr(),
                    ),
                ),
                Functions::V3(f) => (
                    "fmi3GetFloat64",
                    (f.get_float64)(
                        self.handle,
                        references.as_ptr(),
                        references.len(),
                        values.as_mut_ptr(),
                        values.len(),
                    ),
                ),
            }
        };
        self.check(name, status)
    }

    /// FMI 2.0 co-simulation: the first derivatives of inputs over the
    /// coming communication step.
    pub fn set_input_slopes(&mut self, references: &[u32], slopes: &[f64]) -> Result<()> {
        debug_assert_eq!(references.len(), slopes.len());
        let Functions::V2(Fmi2 {
            set_real_input_derivatives: Some(set),
            ..
        }) = &self.binary.functions
        else {
            return Err(self.refused(
                "fmi2SetRealInputDerivatives",
                "not loaded: the FMU does not interpolate inputs".into(),
            ));
        };
        let orders = vec![1 as c_int; references.len()];
        // SAFETY: the three slices hold `len` elements.
        let status = unsafe {
            set(
                self.handle,
                references.as_ptr(),
                references.len(),
                orders.as_ptr(),
                slopes.as_ptr(),
            )
        };
        self.check("fmi2SetRealInputDerivatives", status)
    }

    /// Enter and leave initialization mode at `start_time` (after the start
    /// values are set). A co-simulation FMU is then ready to step; a
    /// model-exchange FMU is in event mode, and [`Component::update_discrete`]
    /// comes next.
    pub fn initialize(&mut self, start_time: f64) -> Result<()> {
        self.binary.refuse_after_fatal("initialize", start_time)?;
        self.time = start_time;
        // SAFETY: a live handle.
        unsafe {
            match &self.binary.functions {
                Functions::V2(f) => {
                    let status = (f.setup_experiment)(self.handle, 0, 0.0, start_time, 0, 0.0);
                    self.check("fmi2SetupExperiment", status)?;
                    let status = (f.enter_initialization_mode)(self.handle);
                    self.check("fmi2EnterInitializationMode", status)?;
                    let status = (f.exit_initialization_mode)(self.handle);
                    self.check("fmi2ExitInitializationMode", status)
                }
                Functions::V3(f) => {
                    let status = (f.enter_initialization_mode)(
                        self.handle,
                        false,
                        0.0,
                        start_time,
                        false,
                        0.0,
                    );
                    self.check("fmi3EnterInitializationMode", status)?;
                    let status = (f.exit_initialization_mode)(self.handle);
                    self.check("fmi3ExitInitializationMode", status)
                }
            }
        }
    }

    /// Co-simulation: advance from `time` by `step`.
    pub fn do_step(&mut self, time: f64, step: f64) -> Result<()> {
        self.binary.refuse_after_fatal("doStep", time)?;
        self.time = time;
        // SAFETY: a live handle; the out-pointers are locals.
        unsafe {
            match &self.binary.functions {
                Functions::V2(Fmi2 {
                    do_step: Some(do_step),
                    ..
                }) => {
                    let status = do_step(self.handle, time, step, 1);
                    self.check("fmi2DoStep", status)
                }
                Functions::V3(Fmi3 {
                    do_step: Some(do_step),
                    ..
                }) => {
                    let (mut event, mut terminate, mut early) = (false, false, false);
                    let mut reached = time;
                    let status = do_step(
                        self.handle,
                        time,
                        step,
                        true,
                        &mut event,
                        &mut terminate,
                        &mut early,
                        &mut reached,
                    );
                    self.check("fmi3DoStep", status)?;
                    if terminate {
                        return Err(self.refused(
                            "fmi3DoStep",
                            format!(
                                "a request to terminate the simulation (reached t = {reached})"
                            ),
                        ));
                    }
                    Ok(())
                }
                _ => Err(self.refused("doStep", "not a co-simulation instance".into())),
            }
        }
    }

    /// Model exchange: the time.
    pub fn set_time(&mut self, time: f64) -> Result<()> {
        self.time = time;
        // SAFETY: a live handle.
        let (name, status) = unsafe {
            match &self.binary.functions {
                Functions::V2(Fmi2 { me: Some(m), .. }) => {
                    ("fmi2SetTime", (m.set_time)(self.handle, time))
                }
                Functions::V3(Fmi3 { me: Some(m), .. }) => {
                    ("fmi3SetTime", (m.set_time)(self.handle, time))
                }
                _ => return Err(self.refused("setTime", "not a model-exchange instance".into())),
            }
        };
        self.check(name, status)
    }

    /// Model exchange: set the continuous states.
    pub fn set_states(&mut self, x: &[f64]) -> Result<()> {
        // SAFETY: a live handle; `x` holds `len` values.
        let (name, status) = unsafe {
            match &self.binary.functions {
                Functions::V2(Fmi2 { me: Some(m), .. }) => (
                    "fmi2SetContinuousStates",
                    (m.set_continuous_states)(self.handle, x.as_ptr(), x.len()),
                ),
                Functions::V3(Fmi3 { me: Some(m), .. }) => (
                    "fmi3SetContinuousStates",
                    (m.set_continuous_states)(self.handle, x.as_ptr(), x.len()),
                ),
                _ => {
                    return Err(self.refused(
                        "setContinuousStates",
                        "not a model-exchange instance".into(),
                    ));
                }
            }
        };
        self.check(name, status)
    }

    /// Model exchange: read the continuous states.
    pub fn get_states(&mut self, x: &mut [f64]) -> Result<()> {
        // SAFETY: a live handle; `x` holds `len` values.
        let (name, status) = unsafe {
            match &self.binary.functions {
                Functions::V2(Fmi2 { me: Some(m), .. }) => (
                    "fmi2GetContinuousStates",
                    (m.get_continuous_states)(self.handle, x.as_mut_ptr(), x.len()),
                ),
                Functions::V3(Fmi3 { me: Some(m), .. }) => (
                    "fmi3GetContinuousStates",
                    (m.get_continuous_states)(self.handle, x.as_mut_ptr(), x.len()),
                ),
                _ => {
                    return Err(self.refused(
                        "getContinuousStates",
                        "not a model-exchange instance".into(),
                    ));
                }
            }
        };
        self.check(name, status)
    }

    /// Model exchange: the state derivatives at the current time, states
    /// and inputs.
    pub fn derivatives(&mut self, dx: &mut [f64]) -> Result<()> {
        // SAFETY: a live handle; `dx` holds `len` values.
        let (name, status) = unsafe {
            match &self.binary.functions {
                Functions::V2(Fmi2 { me: Some(m), .. }) => (
                    "fmi2GetDerivatives",
                    (m.get_derivatives)(self.handle, dx.as_mut_ptr(), dx.len()),
                ),
                Functions::V3(Fmi3 { me: Some(m), .. }) => (
                    "fmi3GetContinuousStateDerivatives",
                    (m.get_derivatives)(self.handle, dx.as_mut_ptr(), dx.len()),
                ),
                _ => {
                    return Err(
                        self.refused("getDerivatives", "not a model-exchange instance".into())
                    );
                }
            }
        };
        self.check(name, status)
    }

    /// Model exchange: enter event mode (from continuous-time mode).
    pub fn enter_event_mode(&mut self) -> Result<()> {
        // SAFETY: a live handle.
        let (name, status) = unsafe {
            match &self.binary.functions {
                Functions::V2(Fmi2 { me: Some(m), .. }) => {
                    ("fmi2EnterEventMode", (m.enter_event_mode)(self.handle))
                }
                Functions::V3(Fmi3 { me: Some(m), .. }) => {
                    ("fmi3EnterEventMode", (m.enter_event_mode)(self.handle))
                }
                _ => {
                    return Err(
                        self.refused("enterEventMode", "not a model-exchange instance".into())
                    );
                }
            }
        };
        self.check(name, status)
    }

    /// Model exchange, in event mode: iterate the discrete states until
    /// they settle, then enter continuous-time mode.
    pub fn update_discrete(&mut self) -> Result<EventUpdate> {
        let mut update = EventUpdate::default();
        // The standard leaves the number of iterations to the FMU; an FMU
        // that never settles is broken, and is told so.
        for _ in 0..1000 {
            // SAFETY: a live handle; the out-pointers are locals.
            let (name, status, again) = unsafe {
                match &self.binary.functions {
                    Functions::V2(Fmi2 { me: Some(m), .. }) => {
                        let mut info = Fmi2EventInfo::default();
                        let status = (m.new_discrete_states)(self.handle, &mut info);
                        update.terminate |= info.terminate_simulation != 0;
                        update.states_changed |= info.values_of_continuous_states_changed != 0;
                        update.next_event_time =
                            (info.next_event_time_defined != 0).then_some(info.next_event_time);
                        (
                            "fmi2NewDiscreteStates",
                            status,
                            info.new_discrete_states_needed != 0,
                        )
                    }
                    Functions::V3(Fmi3 { me: Some(m), .. }) => {
                        let (mut again, mut terminate, mut nominals, mut values, mut defined) =
                            (false, false, false, false, false);
                        let mut next = 0.0;
                        let status = (m.update_discrete_states)(
                            self.handle,
                            &mut again,
                            &mut terminate,
                            &mut nominals,
                            &mut values,
                            &mut defined,
                            &mut next,
                        );
                        update.terminate |= terminate;
                        update.states_changed |= values;
                        update.next_event_time = defined.then_some(next);
                        ("fmi3UpdateDiscreteStates", status, again)
                    }
                    _ => {
                        return Err(self.refused(
                            "updateDiscreteStates",
                            "not a model-exchange instance".into(),
                        ));
                    }
                }
            };
            self.check(name, status)?;
            if update.terminate {
                return Err(self.refused(name, "a request to terminate the simulation".into()));
            }
            if !again {
                // SAFETY: a live handle.
                let (name, status) = unsafe {
                    match &self.binary.functions {
                        Functions::V2(Fmi2 { me: Some(m), .. }) => (
                            "fmi2EnterContinuousTimeMode",
                            (m.enter_continuous_time_mode)(self.handle),
                        ),
                        Functions::V3(Fmi3 { me: Some(m), .. }) => (
                            "fmi3EnterContinuousTimeMode",
                            (m.enter_continuous_time_mode)(self.handle),
                        ),
                        _ => unreachable!("matched above"),
                    }
                };
                self.check(name, status)?;
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
        // SAFETY: a live handle; the out-pointers are locals.
        let (name, status, event, terminate) = unsafe {
            match &self.binary.functions {
                Functions::V2(Fmi2 { me: Some(m), .. }) => {
                    let (mut event, mut terminate) = (0, 0);
                    let status =
                        (m.completed_integrator_step)(self.handle, 1, &mut event, &mut terminate);
                    (
                        "fmi2CompletedIntegratorStep",
                        status,
                        event != 0,
                        terminate != 0,
                    )
                }
                Functions::V3(Fmi3 { me: Some(m), .. }) => {
                    let (mut event, mut terminate) = (false, false);
                    let status = (m.completed_integrator_step)(
                        self.handle,
                        true,
                        &mut event,
                        &mut terminate,
                    );
                    ("fmi3CompletedIntegratorStep", status, event, terminate)
                }
                _ => {
                    return Err(self.refused(
                        "completedIntegratorStep",
                        "not a model-exchange instance".into(),
                    ));
                }
            }
        };
        self.check(name, status)?;
        if terminate {
            return Err(self.refused(name, "a request to terminate the simulation".into()));
        }
        Ok(event)
    }
}
