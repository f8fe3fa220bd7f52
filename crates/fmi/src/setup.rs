//! What an FMU simulation is set up with (variables by name, interface,
//! steps), checked against the FMU's description and loaded: shared by the
//! simulator and its worker processes.

use std::path::PathBuf;
use std::sync::atomic::AtomicUsize;
use std::sync::{Arc, Mutex};

use crate::archive::Unpacked;
use crate::description::{
    Causality, Interface, InterfaceKind, ModelDescription, Variability, Variable,
};
use crate::error::{FmiError, Result};
use crate::ffi::Binary;
use crate::run::{InProcess, Plan, Roles};

/// The most communication (or integration) steps per sample.
pub(crate) const MAX_STEP_DIVISOR: usize = 1 << 16;

/// What the FMU is asked to do, by variable name: everything a worker
/// process needs to set up the same simulation.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub(crate) struct Setup {
    pub path: PathBuf,
    pub parameters: Vec<String>,
    pub inputs: Vec<String>,
    pub outputs: Vec<String>,
    pub noise_inputs: Vec<(String, f64)>,
    pub starts: Vec<(String, f64)>,
    pub interface: Option<InterfaceKind>,
    pub step_divisor: usize,
    pub start_time: f64,
    pub sample_time: f64,
    pub n_samples: usize,
}

/// An FMU opened and checked against a [`Setup`]: its description, the
/// interface in use and the plan of an experiment.
pub(crate) struct Loaded {
    pub unpacked: Unpacked,
    pub interface: Interface,
    pub plan: Plan,
}

impl Loaded {
    pub fn open(setup: &Setup) -> Result<Self> {
        let unpacked = Unpacked::open(&setup.path)?;
        let origin = unpacked.origin.clone();
        if !(1..=MAX_STEP_DIVISOR).contains(&setup.step_divisor) {
            return Err(FmiError::Setting {
                name: "step_divisor",
                value: setup.step_divisor.to_string(),
                reason: format!("give 1 to {MAX_STEP_DIVISOR} steps per sample"),
            });
        }
        if !setup.start_time.is_finite() {
            return Err(FmiError::Setting {
                name: "start_time",
                value: setup.start_time.to_string(),
                reason: "must be finite".into(),
            });
        }
        let md = &unpacked.description;
        let kind = match setup.interface {
            Some(kind) => kind,
            None if md.co_simulation.is_some() => InterfaceKind::CoSimulation,
            None => InterfaceKind::ModelExchange,
        };
        let interface = md
            .interface(kind)
            .ok_or_else(|| FmiError::Interface {
                path: origin.clone(),
                message: format!(
                    "the FMU has no {kind} interface; it has {}",
                    if md.co_simulation.is_some() {
                        "co-simulation"
                    } else {
                        "model exchange"
                    }
                ),
            })?
            .clone();
        if kind == InterfaceKind::ModelExchange && md.event_indicators > 0 {
            return Err(FmiError::Interface {
                path: origin,
                message: format!(
                    "the model-exchange FMU has {} event indicator(s) (state events), which a \
                     fixed-step integrator cannot locate: it would be simulated wrongly. Use its \
                     co-simulation interface if it has one, or export it for co-simulation",
                    md.event_indicators
                ),
            });
        }
        let roles = Roles::check(md, &origin, setup)?;
        // FMI 2.0 co-simulation FMUs that say they interpolate inputs get
        // the straight line to the next sample (the project's convention
        // for continuous-time models); FMI 3.0 has no input
        // derivatives, and others hold inputs between samples.
        let interpolate_inputs = md.version == crate::FmiVersion::V2
            && kind == InterfaceKind::CoSimulation
            && md.can_interpolate_inputs
            && !setup.inputs.is_empty();
        let plan = Plan {
            roles,
            kind,
            interpolate_inputs,
            step_divisor: setup.step_divisor,
            start_time: setup.start_time,
            sample_time: setup.sample_time,
            continuous_states: md.continuous_states,
            origin,
        };
        Ok(Self {
            unpacked,
            interface,
            plan,
        })
    }

    /// Load the binary and instantiate it once, so that a token mismatch
    /// or a missing resource is reported before any experiment.
    pub fn in_process(&self, serial: bool) -> Result<InProcess> {
        let md = &self.unpacked.description;
        let binary = self.unpacked.binary(&self.interface.model_identifier)?;
        let binary = Arc::new(Binary::load(
            &binary,
            md.version,
            self.plan.kind,
            self.plan.interpolate_inputs,
            &self.unpacked.origin,
            &md.token,
            &self.unpacked.resource_location(),
        )?);
        let engine = InProcess {
            binary,
            serial,
            idle: Mutex::new(Vec::new()),
            instances: AtomicUsize::new(0),
        };
        let first = engine.instantiate()?;
        engine.give_back(first);
        Ok(engine)
    }
}

impl Roles {
    fn check(md: &ModelDescription, origin: &str, setup: &Setup) -> Result<Self> {
        let mut used: Vec<(&str, &str)> = Vec::new();
        let mut find = |name: &str, role: &'static str| -> Result<&Variable> {
            let variable = md.variable(name).ok_or_else(|| {
                let similar = md.similar_names(name);
                FmiError::Variable {
                    path: origin.into(),
                    name: name.into(),
                    message: format!(
                        "the FMU has no variable of that name{}; `twostage fmu inspect` lists them",
                        if similar.is_empty() {
                            String::new()
                        } else {
                            format!(" (similar: {})", similar.join(", "))
                        }
                    ),
                }
            })?;
            if let Some((_, other)) = used.iter().find(|(n, _)| *n == name) {
                return Err(FmiError::Variable {
                    path: origin.into(),
                    name: name.into(),
                    message: format!("named as {other} and as {role}: give each variable one role"),
                });
            }
            used.push((&variable.name, role));
            if !variable.is_real_scalar {
                return Err(FmiError::Variable {
                    path: origin.into(),
                    name: name.into(),
                    message: format!(
                        "its type is {}{}: twostage uses real scalar variables only",
                        variable.type_name,
                        if variable.type_name == "Float64" {
                            " array"
                        } else {
                            ""
                        }
                    ),
                });
            }
            Ok(variable)
        };
        let refuse = |v: &Variable, role: &str, wanted: &str| FmiError::Variable {
            path: origin.into(),
            name: v.name.clone(),
            message: format!(
                "it is a {} {} variable, so it cannot be {role}: {wanted}",
                v.variability.as_str(),
                v.causality.as_str()
            ),
        };
        let settable = |v: &Variable| {
            v.causality == Causality::Parameter
                && matches!(v.variability, Variability::Fixed | Variability::Tunable)
        };
        let mut parameters = Vec::new();
        for name in &setup.parameters {
            let v = find(name, "a parameter to estimate")?;
            if !settable(v) {
                return Err(refuse(
                    v,
                    "estimated",
                    "only a parameter with variability fixed or tunable can be set before \
                     initialization (a calculated parameter is computed from others: estimate \
                     those)",
                ));
            }
            parameters.push(v.value_reference);
        }
        let mut inputs = Vec::new();
        let noise_names = setup.noise_inputs.iter().map(|(n, _)| n);
        for (j, name) in setup.inputs.iter().chain(noise_names).enumerate() {
            let role = if j < setup.inputs.len() {
                "an input"
            } else {
                "a noise input"
            };
            let v = find(name, role)?;
            if v.causality != Causality::Input {
                return Err(refuse(v, role, "name one of the FMU's inputs"));
            }
            inputs.push(v.value_reference);
        }
        for (name, sd) in &setup.noise_inputs {
            if !(sd.is_finite() && *sd >= 0.0) {
                return Err(FmiError::Setting {
                    name: "noise input sd",
                    value: format!("{name} = {sd}"),
                    reason: "must be finite and >= 0".into(),
                });
            }
        }
        let mut outputs = Vec::new();
        for name in &setup.outputs {
            let v = find(name, "an output")?;
            if !matches!(v.causality, Causality::Output | Causality::Local) {
                return Err(refuse(
                    v,
                    "measured",
                    "name an output (or a local variable)",
                ));
            }
            outputs.push(v.value_reference);
        }
        let (mut start_references, mut start_values) = (Vec::new(), Vec::new());
        for (name, value) in &setup.starts {
            let v = find(name, "a start value")?;
            if !(settable(v) || v.causality == Causality::Input) {
                return Err(refuse(
                    v,
                    "given a start value",
                    "name a fixed or tunable parameter",
                ));
            }
            if !value.is_finite() {
                return Err(FmiError::Setting {
                    name: "start value",
                    value: format!("{name} = {value}"),
                    reason: "must be finite".into(),
                });
            }
            start_references.push(v.value_reference);
            start_values.push(*value);
        }
        Ok(Self {
            parameters,
            n_measured_inputs: setup.inputs.len(),
            inputs,
            outputs,
            start_references,
            start_values,
        })
    }
}
