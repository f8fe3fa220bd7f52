//! FMI 3.0's functions (`fmi3FunctionTypes.h`, FMI 3.0.1 section 2.3),
//! loaded from a binary, as an [`Api`].

use std::ffi::{CStr, c_char, c_int, c_void};
use std::path::Path;

use libloading::Library;

use super::Symbols;
use super::api::{Api, Call, Discrete, Handle, Instance, NOT_MODEL_EXCHANGE, StepEnd, Unsupported};
use super::log::twostage_fmi_log;
use crate::description::InterfaceKind;
use crate::error::Result;

type Status0 = unsafe extern "C" fn(Handle) -> c_int;
type Vector = unsafe extern "C" fn(Handle, *mut f64, usize) -> c_int;
type ConstVector = unsafe extern "C" fn(Handle, *const f64, usize) -> c_int;
type LogMessage = unsafe extern "C" fn(*mut c_void, c_int, *const c_char, *const c_char);
type IntermediateUpdate =
    unsafe extern "C" fn(*mut c_void, f64, bool, bool, bool, bool, *mut bool, *mut f64);
type InstantiateCoSimulation = unsafe extern "C" fn(
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
    Option<LogMessage>,
    Option<IntermediateUpdate>,
) -> Handle;
type InstantiateModelExchange = unsafe extern "C" fn(
    *const c_char,
    *const c_char,
    *const c_char,
    bool,
    bool,
    *mut c_void,
    Option<LogMessage>,
) -> Handle;
type DoStep = unsafe extern "C" fn(
    Handle,
    f64,
    f64,
    bool,
    *mut bool,
    *mut bool,
    *mut bool,
    *mut f64,
) -> c_int;

pub(super) struct Fmi3 {
    instantiate_co_simulation: Option<InstantiateCoSimulation>,
    instantiate_model_exchange: Option<InstantiateModelExchange>,
    free_instance: unsafe extern "C" fn(Handle),
    enter_initialization_mode: unsafe extern "C" fn(Handle, bool, f64, f64, bool, f64) -> c_int,
    exit_initialization_mode: Status0,
    reset: Status0,
    set_float64: unsafe extern "C" fn(Handle, *const u32, usize, *const f64, usize) -> c_int,
    get_float64: unsafe extern "C" fn(Handle, *const u32, usize, *mut f64, usize) -> c_int,
    do_step: Option<DoStep>,
    me: Option<ModelExchange>,
}

struct ModelExchange {
    set_time: unsafe extern "C" fn(Handle, f64) -> c_int,
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

impl Fmi3 {
    /// The functions of `kind`.
    pub(super) fn load(
        library: &Library,
        kind: InterfaceKind,
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
            instantiate_co_simulation: cs
                .then(|| get.required("fmi3InstantiateCoSimulation"))
                .transpose()?,
            instantiate_model_exchange: (!cs)
                .then(|| get.required("fmi3InstantiateModelExchange"))
                .transpose()?,
            free_instance: get.required("fmi3FreeInstance")?,
            enter_initialization_mode: get.required("fmi3EnterInitializationMode")?,
            exit_initialization_mode: get.required("fmi3ExitInitializationMode")?,
            reset: get.required("fmi3Reset")?,
            set_float64: get.required("fmi3SetFloat64")?,
            get_float64: get.required("fmi3GetFloat64")?,
            do_step: cs.then(|| get.required("fmi3DoStep")).transpose()?,
            me: if cs {
                None
            } else {
                Some(ModelExchange {
                    set_time: get.required("fmi3SetTime")?,
                    set_continuous_states: get.required("fmi3SetContinuousStates")?,
                    get_derivatives: get.required("fmi3GetContinuousStateDerivatives")?,
                    get_continuous_states: get.required("fmi3GetContinuousStates")?,
                    enter_event_mode: get.required("fmi3EnterEventMode")?,
                    update_discrete_states: get.required("fmi3UpdateDiscreteStates")?,
                    enter_continuous_time_mode: get.required("fmi3EnterContinuousTimeMode")?,
                    completed_integrator_step: get.required("fmi3CompletedIntegratorStep")?,
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
impl Api for Fmi3 {
    unsafe fn instantiate(
        &self,
        name: &CStr,
        token: &CStr,
        resources: &CStr,
        environment: *mut c_void,
    ) -> Instance {
        // SAFETY: as the trait says; the log callback is the common sink.
        let handle = unsafe {
            match (
                self.instantiate_co_simulation,
                self.instantiate_model_exchange,
            ) {
                (Some(instantiate), _) => instantiate(
                    name.as_ptr(),
                    token.as_ptr(),
                    resources.as_ptr(),
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
                    name.as_ptr(),
                    token.as_ptr(),
                    resources.as_ptr(),
                    false,
                    true,
                    environment,
                    Some(twostage_fmi_log),
                ),
                (None, None) => std::ptr::null_mut(),
            }
        };
        Instance { handle, keep: None }
    }

    unsafe fn free_instance(&self, handle: Handle) {
        unsafe { (self.free_instance)(handle) }
    }

    unsafe fn reset(&self, handle: Handle) -> Call {
        Call::new("fmi3Reset", unsafe { (self.reset)(handle) })
    }

    unsafe fn set_reals(&self, handle: Handle, references: &[u32], values: &[f64]) -> Call {
        let status = unsafe {
            (self.set_float64)(
                handle,
                references.as_ptr(),
                references.len(),
                values.as_ptr(),
                values.len(),
            )
        };
        Call::new("fmi3SetFloat64", status)
    }

    unsafe fn get_reals(&self, handle: Handle, references: &[u32], values: &mut [f64]) -> Call {
        let status = unsafe {
            (self.get_float64)(
                handle,
                references.as_ptr(),
                references.len(),
                values.as_mut_ptr(),
                values.len(),
            )
        };
        Call::new("fmi3GetFloat64", status)
    }

    unsafe fn set_input_slopes(
        &self,
        _handle: Handle,
        _references: &[u32],
        _slopes: &[f64],
    ) -> std::result::Result<Call, Unsupported> {
        // FMI 3.0 interpolates inputs by clocks and intermediate updates,
        // which the simulator does not use.
        Err((
            "fmi2SetRealInputDerivatives",
            "not loaded: the FMU does not interpolate inputs",
        ))
    }

    unsafe fn initialize(
        &self,
        handle: Handle,
        start_time: f64,
        check: &mut dyn FnMut(Call) -> Result<()>,
    ) -> Result<()> {
        unsafe {
            check(Call::new(
                "fmi3EnterInitializationMode",
                (self.enter_initialization_mode)(handle, false, 0.0, start_time, false, 0.0),
            ))?;
            check(Call::new(
                "fmi3ExitInitializationMode",
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
        let (mut event, mut terminate, mut early) = (false, false, false);
        let mut reached = time;
        let status = unsafe {
            do_step(
                handle,
                time,
                step,
                true,
                &mut event,
                &mut terminate,
                &mut early,
                &mut reached,
            )
        };
        Ok((
            Call::new("fmi3DoStep", status),
            StepEnd {
                terminate_at: terminate.then_some(reached),
            },
        ))
    }

    unsafe fn set_time(&self, handle: Handle, time: f64) -> std::result::Result<Call, Unsupported> {
        let m = self.me("setTime")?;
        Ok(Call::new("fmi3SetTime", unsafe {
            (m.set_time)(handle, time)
        }))
    }

    unsafe fn set_states(
        &self,
        handle: Handle,
        x: &[f64],
    ) -> std::result::Result<Call, Unsupported> {
        let m = self.me("setContinuousStates")?;
        Ok(Call::new("fmi3SetContinuousStates", unsafe {
            (m.set_continuous_states)(handle, x.as_ptr(), x.len())
        }))
    }

    unsafe fn get_states(
        &self,
        handle: Handle,
        x: &mut [f64],
    ) -> std::result::Result<Call, Unsupported> {
        let m = self.me("getContinuousStates")?;
        Ok(Call::new("fmi3GetContinuousStates", unsafe {
            (m.get_continuous_states)(handle, x.as_mut_ptr(), x.len())
        }))
    }

    unsafe fn derivatives(
        &self,
        handle: Handle,
        dx: &mut [f64],
    ) -> std::result::Result<Call, Unsupported> {
        let m = self.me("getDerivatives")?;
        Ok(Call::new("fmi3GetContinuousStateDerivatives", unsafe {
            (m.get_derivatives)(handle, dx.as_mut_ptr(), dx.len())
        }))
    }

    unsafe fn enter_event_mode(&self, handle: Handle) -> std::result::Result<Call, Unsupported> {
        let m = self.me("enterEventMode")?;
        Ok(Call::new("fmi3EnterEventMode", unsafe {
            (m.enter_event_mode)(handle)
        }))
    }

    unsafe fn update_discrete(
        &self,
        handle: Handle,
    ) -> std::result::Result<(Call, Discrete), Unsupported> {
        let m = self.me("updateDiscreteStates")?;
        let (mut again, mut terminate, mut nominals, mut values, mut defined) =
            (false, false, false, false, false);
        let mut next = 0.0;
        let status = unsafe {
            (m.update_discrete_states)(
                handle,
                &mut again,
                &mut terminate,
                &mut nominals,
                &mut values,
                &mut defined,
                &mut next,
            )
        };
        Ok((
            Call::new("fmi3UpdateDiscreteStates", status),
            Discrete {
                again,
                terminate,
                states_changed: values,
                next_event_time: defined.then_some(next),
            },
        ))
    }

    unsafe fn enter_continuous_time_mode(
        &self,
        handle: Handle,
    ) -> std::result::Result<Call, Unsupported> {
        let m = self.me("enterContinuousTimeMode")?;
        Ok(Call::new("fmi3EnterContinuousTimeMode", unsafe {
            (m.enter_continuous_time_mode)(handle)
        }))
    }

    unsafe fn completed_step(
        &self,
        handle: Handle,
    ) -> std::result::Result<(Call, bool, bool), Unsupported> {
        let m = self.me("completedIntegratorStep")?;
        let (mut event, mut terminate) = (false, false);
        let status =
            unsafe { (m.completed_integrator_step)(handle, true, &mut event, &mut terminate) };
        Ok((
            Call::new("fmi3CompletedIntegratorStep", status),
            event,
            terminate,
        ))
    }
}
