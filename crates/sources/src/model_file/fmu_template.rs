//! The starting model file `twostage fmu inspect --write` saves for an FMU.

/// A model file to start from for an FMU, as `twostage fmu inspect
/// --write` saves it: every fixed or tunable real parameter with a uniform
/// prior around its start value, the real inputs driven by white noise,
/// the real outputs measured, and the FMU's suggested step as the sample
/// time. Lines marked CHECK need a modeller's eye.
///
/// ```
/// use twostage_fmi::ModelDescription;
/// use twostage_sources::{fmu_model_file, ModelFile};
/// let xml = r#"<fmiModelDescription fmiVersion="2.0" modelName="tank" guid="{1}">
///   <CoSimulation modelIdentifier="tank"/>
///   <DefaultExperiment stopTime="50" stepSize="0.1"/>
///   <ModelVariables>
///     <ScalarVariable name="area" valueReference="0" causality="parameter" variability="fixed">
///       <Real start="2.0" unit="m2"/></ScalarVariable>
///     <ScalarVariable name="inflow" valueReference="1" causality="input"><Real start="0"/></ScalarVariable>
///     <ScalarVariable name="level" valueReference="2" causality="output"><Real/></ScalarVariable>
///   </ModelVariables>
/// </fmiModelDescription>"#;
/// let text = fmu_model_file(&ModelDescription::parse(xml, "tank.fmu")?, "tank.fmu");
/// let file = ModelFile::parse(&text, "tank.toml").expect("the starting file parses");
/// assert_eq!(file.spec().param_names(), ["area"]);
/// assert_eq!(file.spec().n_samples(), 500);
/// # Ok::<(), twostage_fmi::FmiError>(())
/// ```
pub fn fmu_model_file(description: &twostage_fmi::ModelDescription, fmu: &str) -> String {
    use std::fmt::Write;
    use twostage_fmi::{Causality, Variability};
    let md = description;
    let real = |c: Causality| {
        md.variables
            .iter()
            .filter(move |v| v.is_real_scalar && v.causality == c)
    };
    let parameters: Vec<_> = real(Causality::Parameter)
        .filter(|v| matches!(v.variability, Variability::Fixed | Variability::Tunable))
        .collect();
    let inputs: Vec<&str> = real(Causality::Input).map(|v| v.name.as_str()).collect();
    let outputs: Vec<&str> = real(Causality::Output).map(|v| v.name.as_str()).collect();
    let step = md
        .default_experiment
        .step_size
        .filter(|h| h.is_finite() && *h > 0.0);
    let sample_time = step.unwrap_or(0.01);
    let span = md
        .default_experiment
        .stop_time
        .map(|stop| stop - md.default_experiment.start_time.unwrap_or(0.0));
    let samples = span
        .map(|t| (t / sample_time).round())
        .filter(|n| n.is_finite() && (2.0..=1e6).contains(n))
        .map_or(1000, |n| n as usize);
    let quote = |s: &str| format!("{s:?}");
    let list = |names: &[&str]| {
        names
            .iter()
            .map(|n| quote(n))
            .collect::<Vec<_>>()
            .join(", ")
    };
    let mut out = String::new();
    let _ = writeln!(
        out,
        r#"# A starting model file for the FMU {name}, written by `twostage fmu inspect`.
# Lines marked CHECK are guesses: set them from what you know of the model.
# The reference is `twostage models --template`; docs/fmu.md walks through it.

[model]
name = {name}"#,
        name = quote(&md.model_name)
    );
    if let Some(d) = &md.description {
        let _ = writeln!(out, "description = {}", quote(d));
    }
    let interface = if md.co_simulation.is_some() {
        "co-simulation"
    } else {
        "model-exchange"
    };
    let _ = writeln!(
        out,
        r#"
[source]
fmu = {fmu}
interface = "{interface}"
step_divisor = 1                   # CHECK: doStep (or RK4 steps) per sample

# The parameters to estimate: delete those you know (they keep their start
# values, or set them with start = {{ name = value }} under [source])."#,
        fmu = quote(fmu)
    );
    if parameters.is_empty() {
        let _ = writeln!(
            out,
            r#"# The FMU has no fixed or tunable real parameter: nothing to estimate as is.
[[parameter]]
name = "CHECK"
prior = {{ dist = "uniform", low = 0.0, high = 1.0 }}"#
        );
    }
    for v in &parameters {
        let start = v.start.filter(|s| s.is_finite()).unwrap_or(0.0);
        // Half to one and a half times the start value: a guess to replace.
        let (low, high) = if start.abs() > 0.0 {
            let (a, b) = (0.5 * start, 1.5 * start);
            (a.min(b), a.max(b))
        } else {
            (-1.0, 1.0)
        };
        let note = match (&v.unit, &v.description) {
            (Some(u), Some(d)) => format!(" ({u}): {d}"),
            (Some(u), None) => format!(" ({u})"),
            (None, Some(d)) => format!(": {d}"),
            (None, None) => String::new(),
        };
        let _ = writeln!(
            out,
            r#"[[parameter]]
name = {name}
# CHECK: start value {start}{note}
prior = {{ dist = "uniform", low = {low:?}, high = {high:?} }}"#,
            name = quote(&v.name)
        );
    }
    let _ = writeln!(
        out,
        r#"
[signals]
inputs = [{inputs}]
outputs = [{outputs}]{no_output}
samples = {samples}                    # CHECK: record length
sample_time = {sample_time:?}{step_note}"#,
        inputs = list(&inputs),
        outputs = list(&outputs),
        no_output = if outputs.is_empty() {
            "  # CHECK: the FMU declares no real output; name what is measured"
        } else {
            ""
        },
        step_note = if step.is_some() {
            "                 # the FMU's suggested step"
        } else {
            "                 # CHECK: the FMU suggests no step"
        }
    );
    if !inputs.is_empty() {
        let _ = writeln!(
            out,
            r#"
# CHECK: the input of every experiment (white, chicane or fixed). Inputs
# that are disturbances go under [noise] inputs = [{{ name = ..., sd = ... }}].
[input]
signal = "white"
sd = 1.0"#
        );
    }
    let _ = writeln!(
        out,
        r#"
# No [[preset]]: `twostage train` searches the design by itself (the
# automatic design, 120 s; `--sims M` searches on M simulations instead)
# and prints the [[preset]] block to paste here to train it again without
# searching."#
    );
    out
}
