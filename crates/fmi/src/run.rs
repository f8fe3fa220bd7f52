//! Running one experiment on an instance: co-simulation steps, or model
//! exchange integrated by the project's RK4, with events.

use std::cell::RefCell;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Mutex, PoisonError};

use twostage_models::{IoData, OdeSystem, Rk4};

use crate::description::InterfaceKind;
use crate::error::{FmiError, Result};
use crate::ffi::{Binary, Component};

/// Instances in this process: one per concurrent caller, or one shared.
pub(crate) struct InProcess {
    pub(crate) binary: Arc<Binary>,
    /// One shared instance, one experiment at a time.
    pub(crate) serial: bool,
    pub(crate) idle: Mutex<Vec<Component>>,
    pub(crate) instances: AtomicUsize,
}

impl InProcess {
    /// Whether the FMU returned Fatal: this process cannot run it again.
    pub fn is_fatal(&self) -> bool {
        self.binary.is_fatal()
    }

    pub(crate) fn instantiate(&self) -> Result<Component> {
        let n = self.instances.fetch_add(1, Ordering::Relaxed);
        self.binary.instantiate(&format!("twostage-{n}"))
    }

    /// Keep an instance that finished its experiment, reset for the next.
    pub(crate) fn give_back(&self, mut component: Component) {
        if component.reset().is_ok() {
            self.idle
                .lock()
                .unwrap_or_else(PoisonError::into_inner)
                .push(component);
        }
    }

    /// Run one experiment, the random draws done. An instance that failed
    /// is dropped: the next experiment gets a fresh one.
    pub fn run(&self, plan: &Plan, theta: &[f64], noise: &[f64], out: &mut IoData) -> Result<()> {
        if self.serial {
            // The lock is held for the whole experiment: one instance, one
            // experiment at a time.
            let mut idle = self.idle.lock().unwrap_or_else(PoisonError::into_inner);
            let mut component = match idle.pop() {
                Some(c) => c,
                None => self.instantiate()?,
            };
            let result = plan.run(&mut component, theta, noise, out);
            if result.is_ok() && component.reset().is_ok() {
                idle.push(component);
            }
            return result;
        }
        let idle = self
            .idle
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .pop();
        let mut component = match idle {
            Some(component) => component,
            None => self.instantiate()?,
        };
        let result = plan.run(&mut component, theta, noise, out);
        if result.is_ok() {
            self.give_back(component);
        }
        result
    }
}

/// How one experiment runs: value references and steps.
#[derive(Debug, Clone)]
pub(crate) struct Plan {
    pub(crate) roles: Roles,
    pub(crate) kind: InterfaceKind,
    /// Measured inputs follow the straight line between samples (FMI 2.0
    /// co-simulation with `canInterpolateInputs`).
    pub(crate) interpolate_inputs: bool,
    pub(crate) step_divisor: usize,
    pub(crate) start_time: f64,
    pub(crate) sample_time: f64,
    pub(crate) continuous_states: usize,
    pub(crate) origin: String,
}

impl Plan {
    /// Run one experiment on `component`: `out` holds the inputs, `noise`
    /// the noise inputs sample by sample; the outputs are written to `out`.
    fn run(
        &self,
        component: &mut Component,
        theta: &[f64],
        noise: &[f64],
        out: &mut IoData,
    ) -> Result<()> {
        let roles = &self.roles;
        component.set_reals(&roles.start_references, &roles.start_values)?;
        component.set_reals(&roles.parameters, theta)?;
        component.initialize(self.start_time)?;
        match self.kind {
            InterfaceKind::CoSimulation => self.co_simulate(component, noise, out),
            InterfaceKind::ModelExchange => self.integrate(component, noise, out),
        }
    }

    /// The number of noise inputs.
    pub fn noise_inputs(&self) -> usize {
        self.roles.inputs.len() - self.roles.n_measured_inputs
    }

    /// Set the inputs of sample `k` (measured, then noise) and read its
    /// outputs.
    fn sample(
        &self,
        component: &mut Component,
        k: usize,
        noise: &[f64],
        scratch: &mut Scratch,
        out: &mut IoData,
    ) -> Result<()> {
        let n_u = out.n_inputs();
        let n_noise = self.noise_inputs();
        for j in 0..n_u {
            scratch.inputs[j] = out.input(j)[k];
        }
        scratch.inputs[n_u..].copy_from_slice(&noise[k * n_noise..(k + 1) * n_noise]);
        component.set_reals(&self.roles.inputs, &scratch.inputs)?;
        component.get_reals(&self.roles.outputs, &mut scratch.outputs)?;
        for (j, &y) in scratch.outputs.iter().enumerate() {
            out.output_mut(j)[k] = y;
        }
        Ok(())
    }

    fn co_simulate(
        &self,
        component: &mut Component,
        noise: &[f64],
        out: &mut IoData,
    ) -> Result<()> {
        let n = out.n_samples();
        let mut scratch = Scratch::new(self.roles.inputs.len(), self.roles.outputs.len());
        let (d, step) = self.steps();
        let measured = &self.roles.inputs[..self.roles.n_measured_inputs];
        let mut slopes = vec![0.0; measured.len()];
        let mut values = vec![0.0; measured.len()];
        for k in 0..n {
            self.sample(component, k, noise, &mut scratch, out)?;
            if k + 1 == n {
                break;
            }
            if self.interpolate_inputs {
                for (j, slope) in slopes.iter_mut().enumerate() {
                    let u = out.input(j);
                    *slope = (u[k + 1] - u[k]) / self.sample_time;
                }
            }
            for s in 0..d {
                if self.interpolate_inputs {
                    if s > 0 {
                        // Within a sample, the value on the line at the
                        // sub-step's start.
                        for (j, value) in values.iter_mut().enumerate() {
                            *value = out.input(j)[k] + slopes[j] * (s as f64 * step);
                        }
                        component.set_reals(measured, &values)?;
                    }
                    component.set_input_slopes(measured, &slopes)?;
                }
                // From the step count, so time does not drift by rounding.
                component.do_step(self.start_time + (k * d + s) as f64 * step, step)?;
            }
        }
        Ok(())
    }

    /// Model exchange: the project's RK4, the inputs held over each sample.
    fn integrate(&self, component: &mut Component, noise: &[f64], out: &mut IoData) -> Result<()> {
        let mut next_event = component.update_discrete()?.next_event_time;
        let mut x = vec![0.0; self.continuous_states];
        component.get_states(&mut x)?;
        let n = out.n_samples();
        let mut scratch = Scratch::new(self.roles.inputs.len(), self.roles.outputs.len());
        let (d, step) = self.steps();
        let mut rk4 = Rk4::new(x.len());
        let t0 = self.start_time;
        for k in 0..n {
            component.set_time(t0 + (k * d) as f64 * step)?;
            component.set_states(&x)?;
            self.sample(component, k, noise, &mut scratch, out)?;
            if k + 1 == n {
                break;
            }
            for s in 0..d {
                let t = t0 + (k * d + s) as f64 * step;
                let end = t0 + (k * d + s + 1) as f64 * step;
                let system = Derivatives {
                    dim: x.len(),
                    component: RefCell::new(&mut *component),
                    failure: RefCell::new(None),
                };
                rk4.step(&system, t, step, &mut x);
                if let Some(failure) = system.failure.into_inner() {
                    return Err(failure);
                }
                component.set_time(end)?;
                component.set_states(&x)?;
                let mut event = component.completed_step()?;
                if let Some(at) = next_event {
                    let tolerance = 1e-9 * (step + end.abs());
                    if at < end - tolerance && at > t + tolerance {
                        return Err(FmiError::Interface {
                            path: self.origin.clone(),
                            message: format!(
                                "a time event at t = {at} falls inside the integration step \
                                 [{t}, {end}]; the fixed step cannot honour it. Choose a \
                                 sample time or step divisor that puts it on the grid, or use \
                                 co-simulation"
                            ),
                        });
                    }
                    event |= at <= end + tolerance;
                }
                if event {
                    component.enter_event_mode()?;
                    let update = component.update_discrete()?;
                    next_event = update.next_event_time;
                    if update.states_changed {
                        component.get_states(&mut x)?;
                    }
                }
            }
        }
        Ok(())
    }

    /// Steps per sample and their size.
    fn steps(&self) -> (usize, f64) {
        (
            self.step_divisor,
            self.sample_time / self.step_divisor as f64,
        )
    }
}

/// Per-experiment buffers for one sample's inputs and outputs.
struct Scratch {
    inputs: Vec<f64>,
    outputs: Vec<f64>,
}

impl Scratch {
    fn new(inputs: usize, outputs: usize) -> Self {
        Self {
            inputs: vec![0.0; inputs],
            outputs: vec![0.0; outputs],
        }
    }
}

/// A model-exchange instance as an ODE right-hand side for [`Rk4`]; the
/// first failing call is kept and reported after the step.
struct Derivatives<'c> {
    dim: usize,
    component: RefCell<&'c mut Component>,
    failure: RefCell<Option<FmiError>>,
}

impl OdeSystem for Derivatives<'_> {
    fn dim(&self) -> usize {
        self.dim
    }

    fn rhs(&self, t: f64, x: &[f64], dx: &mut [f64]) {
        if self.failure.borrow().is_some() {
            dx.fill(0.0);
            return;
        }
        let mut component = self.component.borrow_mut();
        let result = component
            .set_time(t)
            .and_then(|()| component.set_states(x))
            .and_then(|()| component.derivatives(dx));
        if let Err(e) = result {
            dx.fill(0.0);
            *self.failure.borrow_mut() = Some(e);
        }
    }
}

/// The value references of each role.
#[derive(Debug, Clone)]
pub(crate) struct Roles {
    pub(crate) parameters: Vec<u32>,
    /// The measured inputs, then the noise inputs.
    pub(crate) inputs: Vec<u32>,
    pub(crate) n_measured_inputs: usize,
    pub(crate) outputs: Vec<u32>,
    pub(crate) start_references: Vec<u32>,
    pub(crate) start_values: Vec<f64>,
}
