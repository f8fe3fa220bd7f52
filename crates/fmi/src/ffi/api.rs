//! What an instance can be asked, once per FMI version: each version's
//! function table implements [`Api`], so that a [`Component`](super::Component)
//! method is one call, not a match on the version.

use std::ffi::{CStr, c_int, c_void};

/// An instance of an FMU, as its binary returned it.
pub(super) type Handle = *mut c_void;

/// One call into the FMU: the standard's name of the function, for
/// messages, and the status it returned.
#[derive(Debug, Clone, Copy)]
pub(super) struct Call {
    pub(super) function: &'static str,
    pub(super) status: c_int,
}

impl Call {
    pub(super) fn new(function: &'static str, status: c_int) -> Self {
        Self { function, status }
    }
}

/// What an instance of this interface cannot do: the call's generic name
/// and why, for the error.
pub(super) type Unsupported = (&'static str, &'static str);

/// A co-simulation instance's step does not do this.
pub(super) const NOT_MODEL_EXCHANGE: &str = "not a model-exchange instance";

/// How a co-simulation step ended, beyond its status.
#[derive(Debug, Clone, Copy, Default)]
pub(super) struct StepEnd {
    /// The FMU asks to end the simulation, having reached this time.
    pub(super) terminate_at: Option<f64>,
}

/// One event iteration's outcome (FMI 2.0 `fmi2EventInfo`, FMI 3.0
/// `fmi3UpdateDiscreteStates`).
#[derive(Debug, Clone, Copy, Default)]
pub(super) struct Discrete {
    pub(super) again: bool,
    pub(super) terminate: bool,
    pub(super) states_changed: bool,
    pub(super) next_event_time: Option<f64>,
}

/// An instance created by [`Api::instantiate`], with what must live as
/// long as it does.
pub(super) struct Instance {
    pub(super) handle: Handle,
    /// FMI 2.0's callback table (FMI 3.0 takes function pointers).
    pub(super) keep: Option<Box<dyn std::any::Any + Send>>,
}

/// The functions of one FMI version, loaded from a binary. Every method
/// is unsafe for its caller: it takes a handle that this very table
/// instantiated and did not free, and slices whose lengths the FMU is told.
pub(super) trait Api: Send + Sync {
    /// A new instance named `name`, logging into `environment` (the
    /// instance's log).
    ///
    /// # Safety
    /// The strings and `environment` outlive the instance.
    unsafe fn instantiate(
        &self,
        name: &CStr,
        token: &CStr,
        resources: &CStr,
        environment: *mut c_void,
    ) -> Instance;
    /// # Safety
    /// A live handle, freed once.
    unsafe fn free_instance(&self, handle: Handle);
    /// # Safety
    /// A live handle.
    unsafe fn reset(&self, handle: Handle) -> Call;
    /// # Safety
    /// A live handle; slices of one length.
    unsafe fn set_reals(&self, handle: Handle, references: &[u32], values: &[f64]) -> Call;
    /// # Safety
    /// A live handle; slices of one length.
    unsafe fn get_reals(&self, handle: Handle, references: &[u32], values: &mut [f64]) -> Call;
    /// First derivatives of inputs over the next communication step, where
    /// the version and the loaded functions have them.
    ///
    /// # Safety
    /// A live handle; slices of one length.
    unsafe fn set_input_slopes(
        &self,
        handle: Handle,
        references: &[u32],
        slopes: &[f64],
    ) -> Result<Call, Unsupported>;
    /// Enter and leave initialization mode at `start_time`; `check`
    /// returns the first failed call's error, and ends the sequence.
    ///
    /// # Safety
    /// A live handle.
    unsafe fn initialize(
        &self,
        handle: Handle,
        start_time: f64,
        check: &mut dyn FnMut(Call) -> crate::error::Result<()>,
    ) -> crate::error::Result<()>;
    /// Co-simulation: one communication step.
    ///
    /// # Safety
    /// A live handle.
    unsafe fn do_step(
        &self,
        handle: Handle,
        time: f64,
        step: f64,
    ) -> Result<(Call, StepEnd), Unsupported>;
    /// # Safety
    /// A live handle.
    unsafe fn set_time(&self, handle: Handle, time: f64) -> Result<Call, Unsupported>;
    /// # Safety
    /// A live handle; `x` holds the states.
    unsafe fn set_states(&self, handle: Handle, x: &[f64]) -> Result<Call, Unsupported>;
    /// # Safety
    /// A live handle; `x` holds the states.
    unsafe fn get_states(&self, handle: Handle, x: &mut [f64]) -> Result<Call, Unsupported>;
    /// # Safety
    /// A live handle; `dx` holds the states.
    unsafe fn derivatives(&self, handle: Handle, dx: &mut [f64]) -> Result<Call, Unsupported>;
    /// # Safety
    /// A live handle.
    unsafe fn enter_event_mode(&self, handle: Handle) -> Result<Call, Unsupported>;
    /// # Safety
    /// A live handle.
    unsafe fn update_discrete(&self, handle: Handle) -> Result<(Call, Discrete), Unsupported>;
    /// # Safety
    /// A live handle.
    unsafe fn enter_continuous_time_mode(&self, handle: Handle) -> Result<Call, Unsupported>;
    /// The FMU's answer to a completed integrator step: whether it asks
    /// for event mode, and whether it asks to terminate.
    ///
    /// # Safety
    /// A live handle.
    unsafe fn completed_step(&self, handle: Handle) -> Result<(Call, bool, bool), Unsupported>;
}
