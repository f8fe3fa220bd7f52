//! FMI 2.0's functions (`fmi2FunctionTypes.h`, FMI 2.0.4 section 2.1),
//! loaded from a binary, as an [`Api`].

use std::ffi::{CStr, c_char, c_int, c_void};
use std::path::Path;

use libloading::Library;

use super::Symbols;
use super::api::{Api, Call, Discrete, Handle, Instance, NOT_MODEL_EXCHANGE, StepEnd, Unsupported};
use crate::description::InterfaceKind;
use crate::error::Result;

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
struct Callbacks {
    logger:
        unsafe extern "C" fn(*mut c_void, *const c_char, c_int, *const c_char, *const c_char, ...),
    allocate_memory: unsafe extern "C" fn(usize, usize) -> *mut c_void,
    free_memory: unsafe extern "C" fn(*mut c_void),
    step_finished: Option<unsafe extern "C" fn(*mut c_void, c_int)>,
    component_environment: *mut c_void,
}

// SAFETY: the table is only read, by the FMU, through the instance it
// belongs to; the environment pointer is the instance's own log.
unsafe impl Send for Callbacks {}

/// `fmi2EventInfo`.
#[repr(C)]
#[derive(Default)]
struct EventInfo {
    new_discrete_states_needed: c_int,
    terminate_simulation: c_int,
    nominals_of_continuous_states_changed: c_int,
    values_of_continuous_states_changed: c_int,
    next_event_time_defined: c_int,
    next_event_time: f64,
}

type Status0 = unsafe extern "C" fn(Handle) -> c_int;
type Vector = unsafe extern "C" fn(Handle, *mut f64, usize) -> c_int;
type ConstVector = unsafe extern "C" fn(Handle, *const f64, usize) -> c_int;
type InputDerivatives =
    unsafe extern "C" fn(Handle, *const u32, usize, *const c_int, *const f64) -> c_int;

pub(super) struct Fmi2 {
    kind: InterfaceKind,
    instantiate: unsafe extern "C" fn(
        *const c_char,
        c_int,
        *const c_char,
        *const c_char,
        *const Callbacks,
        c_int,
        c_int,
    ) -> Handle,
    free_instance: unsafe extern "C" fn(Handle),
    setup_experiment: unsafe extern "C" fn(Handle, c_int, f64, f64, c_int, f64) -> c_int,
    enter_initialization_mode: Status0,
    exit_initialization_mode: Status0,
    reset: Status0,
    set_real: unsafe extern "C" fn(Handle, *const u32, usize, *const f64) -> c_int,
    get_real: unsafe extern "C" fn(Handle, *const u32, usize, *mut f64) -> c_int,
    do_step: Option<unsafe extern "C" fn(Handle, f64, f64, c_int) -> c_int>,
    set_real_input_derivatives: Option<InputDerivatives>,
    me: Option<ModelExchange>,
}

struct ModelExchange {
    set_time: unsafe extern "C" fn(Handle, f64) -> c_int,
    set_continuous_states: ConstVector,
    get_derivatives: Vector,
    get_continuous_states: Vector,
    enter_event_mode: Status0,
    new_discrete_states: unsafe extern "C" fn(Handle, *mut EventInfo) -> c_int,
    enter_continuous_time_mode: Status0,
    completed_integrator_step: unsafe extern "C" fn(Handle, c_int, *mut c_int, *mut c_int) -> c_int,
}

impl Fmi2 {
    /// The functions of `kind` (and the input derivatives if
    /// `interpolate_inputs`).
    pub(super) fn load(
        library: &Library,
        kind: InterfaceKind,
        interpolate_inputs: bool,
        origin: &str,
        binary: &Path,
    ) -> Result<Self> {
        let get = Symbols {
            library,
            origin,
            binary,
        };
        let cs = kind == InterfaceKind::CoSimulation;
        Ok(Self {
            kind,
            instantiate: get.required("fmi2Instantiate")?,
            free_instance: get.required("fmi2FreeInstance")?,
            setup_experiment: get.required("fmi2SetupExperiment")?,
            enter_initialization_mode: get.required("fmi2EnterInitializationMode")?,
            exit_initialization_mode: get.required("fmi2ExitInitializationMode")?,
            reset: get.required("fmi2Reset")?,
            set_real: get.required("fmi2SetReal")?,
            get_real: get.required("fmi2GetReal")?,
            do_step: cs.then(|| get.required("fmi2DoStep")).transpose()?,
            set_real_input_derivatives: interpolate_inputs
                .then(|| get.required("fmi2SetRealInputDerivatives"))
                .transpose()?,
            me: if cs {
                None
            } else {
                Some(ModelExchange {
                    set_time: get.required("fmi2SetTime")?,
                    set_continuous_states: get.required("fmi2SetContinuousStates")?,
                    get_derivatives: get.required("fmi2GetDerivatives")?,
                    get_continuous_states: get.required("fmi2GetContinuousStates")?,
                    enter_event_mode: get.required("fmi2EnterEventMode")?,
                    new_discrete_states: get.required("fmi2NewDiscreteStates")?,
                    enter_continuous_time_mode: get.required("fmi2EnterContinuousTimeMode")?,
                    completed_integrator_step: get.required("fmi2CompletedIntegratorStep")?,
                })
            },
        })
    }

    fn me(&self, generic: &'static str) -> std::result::Result<&ModelExchange, Unsupported> {
        self.me.as_ref().ok_or((generic, NOT_MODEL_EXCHANGE))
    }
}

// SAFETY (every method): the caller passes a live handle of this table and
// slices of the lengths passed on; the pointers are the standard's
// signatures, loaded by name.
impl Api for Fmi2 {
    unsafe fn instantiate(
        &self,
        name: &CStr,
        token: &CStr,
        resources: &CStr,
        environment: *mut c_void,
    ) -> Instance {
        let table = Box::new(Callbacks {
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
        // SAFETY: as the trait says; the table lives in the instance.
        let handle = unsafe {
            (self.instantiate)(
                name.as_ptr(),
                kind,
                token.as_ptr(),
                resources.as_ptr(),
                &*table,
                0,
                1,
            )
        };
        Instance {
            handle,
            keep: Some(table),
        }
    }

    unsafe fn free_instance(&self, handle: Handle) {
        unsafe { (self.free_instance)(handle) }
    }

    unsafe fn reset(&self, handle: Handle) -> Call {
        Call::new("fmi2Reset", unsafe { (self.reset)(handle) })
    }

    unsafe fn set_reals(&self, handle: Handle, references: &[u32], values: &[f64]) -> Call {
        let status = unsafe {
            (self.set_real)(
                handle,
                references.as_ptr(),
                references.len(),
                values.as_ptr(),
            )
        };
        Call::new("fmi2SetReal", status)
    }

    unsafe fn get_reals(&self, handle: Handle, references: &[u32], values: &mut [f64]) -> Call {
        let status = unsafe {
            (self.get_real)(
                handle,
                references.as_ptr(),
                references.len(),
                values.as_mut_ptr(),
            )
        };
        Call::new("fmi2GetReal", status)
    }

    unsafe fn set_input_slopes(
        &self,
        handle: Handle,
        references: &[u32],
        slopes: &[f64],
    ) -> std::result::Result<Call, Unsupported> {
        let set = self.set_real_input_derivatives.ok_or((
            "fmi2SetRealInputDerivatives",
            "not loaded: the FMU does not interpolate inputs",
        ))?;
        let orders = vec![1 as c_int; references.len()];
        let status = unsafe {
            set(
                handle,
                references.as_ptr(),
                references.len(),
                orders.as_ptr(),
                slopes.as_ptr(),
            )
        };
        Ok(Call::new("fmi2SetRealInputDerivatives", status))
    }

    unsafe fn initialize(
        &self,
        handle: Handle,
        start_time: f64,
        check: &mut dyn FnMut(Call) -> Result<()>,
    ) -> Result<()> {
        unsafe {
            check(Call::new(
                "fmi2SetupExperiment",
                (self.setup_experiment)(handle, 0, 0.0, start_time, 0, 0.0),
            ))?;
            check(Call::new(
                "fmi2EnterInitializationMode",
                (self.enter_initialization_mode)(handle),
            ))?;
            check(Call::new(
                "fmi2ExitInitializationMode",
                (self.exit_initialization_mode)(handle),
            ))
        }
    }

    unsafe fn do_step(
        &self,
        handle: Handle,
        time: f64,
        step: f64,
    ) -> std::result::Result<(Call, StepEnd), Unsupported> {
        let do_step = self
            .do_step
            .ok_or(("doStep", "not a co-simulation instance"))?;
        let status = unsafe { do_step(handle, time, step, 1) };
        Ok((Call::new("fmi2DoStep", status), StepEnd::default()))
    }

    unsafe fn set_time(&self, handle: Handle, time: f64) -> std::result::Result<Call, Unsupported> {
        let m = self.me("setTime")?;
        Ok(Call::new("fmi2SetTime", unsafe {
            (m.set_time)(handle, time)
        }))
    }

    unsafe fn set_states(
        &self,
        handle: Handle,
        x: &[f64],
    ) -> std::result::Result<Call, Unsupported> {
        let m = self.me("setContinuousStates")?;
        Ok(Call::new("fmi2SetContinuousStates", unsafe {
            (m.set_continuous_states)(handle, x.as_ptr(), x.len())
        }))
    }

    unsafe fn get_states(
        &self,
        handle: Handle,
        x: &mut [f64],
    ) -> std::result::Result<Call, Unsupported> {
        let m = self.me("getContinuousStates")?;
        Ok(Call::new("fmi2GetContinuousStates", unsafe {
            (m.get_continuous_states)(handle, x.as_mut_ptr(), x.len())
        }))
    }

    unsafe fn derivatives(
        &self,
        handle: Handle,
        dx: &mut [f64],
    ) -> std::result::Result<Call, Unsupported> {
        let m = self.me("getDerivatives")?;
        Ok(Call::new("fmi2GetDerivatives", unsafe {
            (m.get_derivatives)(handle, dx.as_mut_ptr(), dx.len())
        }))
    }

    unsafe fn enter_event_mode(&self, handle: Handle) -> std::result::Result<Call, Unsupported> {
        let m = self.me("enterEventMode")?;
        Ok(Call::new("fmi2EnterEventMode", unsafe {
            (m.enter_event_mode)(handle)
        }))
    }

    unsafe fn update_discrete(
        &self,
        handle: Handle,
    ) -> std::result::Result<(Call, Discrete), Unsupported> {
        let m = self.me("updateDiscreteStates")?;
        let mut info = EventInfo::default();
        let status = unsafe { (m.new_discrete_states)(handle, &mut info) };
        Ok((
            Call::new("fmi2NewDiscreteStates", status),
            Discrete {
                again: info.new_discrete_states_needed != 0,
                terminate: info.terminate_simulation != 0,
                states_changed: info.values_of_continuous_states_changed != 0,
                next_event_time: (info.next_event_time_defined != 0)
                    .then_some(info.next_event_time),
            },
        ))
    }

    unsafe fn enter_continuous_time_mode(
        &self,
        handle: Handle,
    ) -> std::result::Result<Call, Unsupported> {
        let m = self.me("enterContinuousTimeMode")?;
        Ok(Call::new("fmi2EnterContinuousTimeMode", unsafe {
            (m.enter_continuous_time_mode)(handle)
        }))
    }

    unsafe fn completed_step(
        &self,
        handle: Handle,
    ) -> std::result::Result<(Call, bool, bool), Unsupported> {
        let m = self.me("completedIntegratorStep")?;
        let (mut event, mut terminate) = (0, 0);
        let status =
            unsafe { (m.completed_integrator_step)(handle, 1, &mut event, &mut terminate) };
        Ok((
            Call::new("fmi2CompletedIntegratorStep", status),
            event != 0,
            terminate != 0,
        ))
    }
}
