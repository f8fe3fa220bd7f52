//! `modelDescription.xml`: what an FMU says about itself (FMI 2.0 section
//! 2.2, FMI 3.0 section 2.4). Only what simulation needs is kept: the
//! interfaces, the scalar real variables with their roles, the number of
//! continuous states and of event indicators.

use std::collections::HashMap;

use crate::error::{FmiError, Result};

/// The FMI version of an FMU.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[non_exhaustive]
pub enum FmiVersion {
    /// FMI 2.0.x.
    V2,
    /// FMI 3.0.x.
    V3,
}

impl std::fmt::Display for FmiVersion {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Self::V2 => "2.0",
            Self::V3 => "3.0",
        })
    }
}

/// How an FMU is simulated.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum InterfaceKind {
    /// The FMU brings its own solver; the importer calls `doStep`.
    CoSimulation,
    /// The FMU gives derivatives; the importer integrates.
    ModelExchange,
}

impl std::fmt::Display for InterfaceKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Self::CoSimulation => "co-simulation",
            Self::ModelExchange => "model exchange",
        })
    }
}

impl std::str::FromStr for InterfaceKind {
    type Err = FmiError;
    fn from_str(s: &str) -> Result<Self> {
        match s {
            "co-simulation" | "cs" => Ok(Self::CoSimulation),
            "model-exchange" | "me" => Ok(Self::ModelExchange),
            other => Err(FmiError::Setting {
                name: "interface",
                value: other.to_string(),
                reason: "use \"co-simulation\" or \"model-exchange\"".into(),
            }),
        }
    }
}

/// One interface an FMU implements.
#[derive(Debug, Clone, PartialEq)]
pub struct Interface {
    /// Co-simulation or model exchange.
    pub kind: InterfaceKind,
    /// The name of the binary and, for FMI 2.0, the functions' prefix.
    pub model_identifier: String,
    /// The FMU may be instantiated only once per process.
    pub once_per_process: bool,
    /// The FMU needs an external tool running (refused: it cannot run in
    /// parallel workers).
    pub needs_execution_tool: bool,
}

/// The role of a variable (FMI's causality).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[non_exhaustive]
pub enum Causality {
    /// A parameter, set before initialization.
    Parameter,
    /// Computed by the FMU from parameters.
    CalculatedParameter,
    /// A parameter that changes the FMU's structure (FMI 3.0).
    StructuralParameter,
    /// An input.
    Input,
    /// An output.
    Output,
    /// Internal to the FMU.
    Local,
    /// The independent variable (time).
    Independent,
}

impl Causality {
    fn parse(text: &str) -> Option<Self> {
        Some(match text {
            "parameter" => Self::Parameter,
            "calculatedParameter" => Self::CalculatedParameter,
            "structuralParameter" => Self::StructuralParameter,
            "input" => Self::Input,
            "output" => Self::Output,
            "local" => Self::Local,
            "independent" => Self::Independent,
            _ => return None,
        })
    }

    /// The standard's word.
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Parameter => "parameter",
            Self::CalculatedParameter => "calculatedParameter",
            Self::StructuralParameter => "structuralParameter",
            Self::Input => "input",
            Self::Output => "output",
            Self::Local => "local",
            Self::Independent => "independent",
        }
    }
}

/// How a variable may change (FMI's variability).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[non_exhaustive]
pub enum Variability {
    /// Never.
    Constant,
    /// Only before initialization.
    Fixed,
    /// At events, by the importer.
    Tunable,
    /// At events.
    Discrete,
    /// Any time.
    Continuous,
}

impl Variability {
    fn parse(text: &str) -> Option<Self> {
        Some(match text {
            "constant" => Self::Constant,
            "fixed" => Self::Fixed,
            "tunable" => Self::Tunable,
            "discrete" => Self::Discrete,
            "continuous" => Self::Continuous,
            _ => return None,
        })
    }

    /// The standard's word.
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Constant => "constant",
            Self::Fixed => "fixed",
            Self::Tunable => "tunable",
            Self::Discrete => "discrete",
            Self::Continuous => "continuous",
        }
    }
}

/// One variable of an FMU.
#[derive(Debug, Clone, PartialEq)]
pub struct Variable {
    /// Its name.
    pub name: String,
    /// The handle the FMI functions take.
    pub value_reference: u32,
    /// Its role.
    pub causality: Causality,
    /// How it may change.
    pub variability: Variability,
    /// A scalar real (FMI 2.0 `Real`, FMI 3.0 `Float64` without
    /// dimensions): the only kind twostage sets and reads.
    pub is_real_scalar: bool,
    /// The type as the description names it (`Real`, `Float64`, `Integer`...).
    pub type_name: String,
    /// Its start value, if it has one and it is real.
    pub start: Option<f64>,
    /// Its unit, if the description gives one.
    pub unit: Option<String>,
    /// What it is, for people.
    pub description: Option<String>,
    /// Its line in modelDescription.xml.
    pub line: usize,
}

/// The default experiment the FMU suggests.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct DefaultExperiment {
    /// Start time.
    pub start_time: Option<f64>,
    /// Stop time.
    pub stop_time: Option<f64>,
    /// Step size.
    pub step_size: Option<f64>,
}

/// What `modelDescription.xml` says.
///
/// ```
/// use twostage_fmi::{Causality, FmiVersion, ModelDescription};
/// let xml = r#"<?xml version="1.0"?>
/// <fmiModelDescription fmiVersion="2.0" modelName="decay" guid="{1}">
///   <CoSimulation modelIdentifier="decay"/>
///   <ModelVariables>
///     <ScalarVariable name="k" valueReference="0" causality="parameter" variability="fixed">
///       <Real start="1.5" unit="1/s"/>
///     </ScalarVariable>
///     <ScalarVariable name="x" valueReference="1" causality="output"><Real/></ScalarVariable>
///   </ModelVariables>
/// </fmiModelDescription>"#;
/// let md = ModelDescription::parse(xml, "decay.fmu")?;
/// assert_eq!(md.version, FmiVersion::V2);
/// let k = md.variable("k").unwrap();
/// assert_eq!((k.causality, k.start), (Causality::Parameter, Some(1.5)));
/// # Ok::<(), twostage_fmi::FmiError>(())
/// ```
#[derive(Debug, Clone, PartialEq)]
pub struct ModelDescription {
    /// FMI 2.0 or 3.0.
    pub version: FmiVersion,
    /// The model's name.
    pub model_name: String,
    /// What the model is, for people.
    pub description: Option<String>,
    /// The token the binary checks at instantiation (FMI 2.0 `guid`, FMI
    /// 3.0 `instantiationToken`).
    pub token: String,
    /// The co-simulation interface, if the FMU has one.
    pub co_simulation: Option<Interface>,
    /// The model-exchange interface, if the FMU has one.
    pub model_exchange: Option<Interface>,
    /// FMI 2.0 co-simulation: the FMU takes input derivatives.
    pub can_interpolate_inputs: bool,
    /// Every variable, in the order of the description.
    pub variables: Vec<Variable>,
    /// The number of continuous states (model exchange).
    pub continuous_states: usize,
    /// The number of event indicators (state events, model exchange).
    pub event_indicators: usize,
    /// The experiment the FMU suggests.
    pub default_experiment: DefaultExperiment,
    by_name: HashMap<String, usize>,
}

impl ModelDescription {
    /// Parse the text of `modelDescription.xml`; `path` names the FMU in
    /// messages.
    ///
    /// # Errors
    /// [`FmiError::Description`] naming the line for malformed XML or a
    /// missing attribute, [`FmiError::UnsupportedVersion`] for FMI 1.0 and
    /// other versions.
    pub fn parse(text: &str, path: &str) -> Result<Self> {
        let doc = roxmltree::Document::parse(text).map_err(|e| FmiError::Description {
            path: path.into(),
            line: Some(e.pos().row as usize),
            message: format!("not well-formed XML: {e}"),
        })?;
        let at = Reader { doc: &doc, path };
        let root = doc.root_element();
        if root.tag_name().name() != "fmiModelDescription" {
            return Err(at.error(
                root,
                format!(
                    "the root element is <{}>, not <fmiModelDescription>",
                    root.tag_name().name()
                ),
            ));
        }
        let version_text = at.required(root, "fmiVersion")?;
        let version = if version_text.starts_with("2.") {
            FmiVersion::V2
        } else if version_text.starts_with("3.") {
            FmiVersion::V3
        } else {
            return Err(FmiError::UnsupportedVersion {
                path: path.into(),
                version: version_text.to_string(),
            });
        };
        let token_key = match version {
            FmiVersion::V2 => "guid",
            FmiVersion::V3 => "instantiationToken",
        };
        let mut md = Self {
            version,
            model_name: at.required(root, "modelName")?.to_string(),
            description: root.attribute("description").map(str::to_string),
            token: at.required(root, token_key)?.to_string(),
            co_simulation: None,
            model_exchange: None,
            can_interpolate_inputs: false,
            variables: Vec::new(),
            continuous_states: 0,
            event_indicators: 0,
            default_experiment: DefaultExperiment::default(),
            by_name: HashMap::new(),
        };
        if version == FmiVersion::V2 {
            md.event_indicators = at.count(root, "numberOfEventIndicators")?;
        }
        let units = at.declared_units(root, version);
        for child in root.children().filter(roxmltree::Node::is_element) {
            match child.tag_name().name() {
                "CoSimulation" => {
                    md.can_interpolate_inputs = at.flag(child, "canInterpolateInputs")?;
                    md.co_simulation = Some(at.interface(child, InterfaceKind::CoSimulation)?);
                }
                "ModelExchange" => {
                    md.model_exchange = Some(at.interface(child, InterfaceKind::ModelExchange)?);
                }
                "DefaultExperiment" => {
                    md.default_experiment = DefaultExperiment {
                        start_time: at.number(child, "startTime")?,
                        stop_time: at.number(child, "stopTime")?,
                        step_size: at.number(child, "stepSize")?,
                    };
                }
                "ModelVariables" => {
                    for node in child.children().filter(roxmltree::Node::is_element) {
                        let variable = at.variable(node, version, &units)?;
                        if md
                            .by_name
                            .insert(variable.name.clone(), md.variables.len())
                            .is_some()
                        {
                            return Err(at.error(
                                node,
                                format!("the variable name '{}' is used twice", variable.name),
                            ));
                        }
                        md.variables.push(variable);
                    }
                }
                "ModelStructure" => {
                    let (states, indicators) = match version {
                        FmiVersion::V2 => (
                            child
                                .children()
                                .find(|n| n.has_tag_name("Derivatives"))
                                .map_or(0, |d| {
                                    d.children().filter(|n| n.has_tag_name("Unknown")).count()
                                }),
                            md.event_indicators,
                        ),
                        FmiVersion::V3 => (
                            child
                                .children()
                                .filter(|n| n.has_tag_name("ContinuousStateDerivative"))
                                .count(),
                            child
                                .children()
                                .filter(|n| n.has_tag_name("EventIndicator"))
                                .count(),
                        ),
                    };
                    md.continuous_states = states;
                    md.event_indicators = indicators;
                }
                _ => {}
            }
        }
        if md.co_simulation.is_none() && md.model_exchange.is_none() {
            return Err(at.error(
                root,
                "the FMU declares neither <CoSimulation> nor <ModelExchange>: nothing to run \
                 (a scheduled-execution FMU cannot be simulated by twostage)"
                    .into(),
            ));
        }
        Ok(md)
    }

    /// A variable by name.
    pub fn variable(&self, name: &str) -> Option<&Variable> {
        self.by_name.get(name).map(|&i| &self.variables[i])
    }

    /// The interface of `kind`, if the FMU has it.
    pub fn interface(&self, kind: InterfaceKind) -> Option<&Interface> {
        match kind {
            InterfaceKind::CoSimulation => self.co_simulation.as_ref(),
            InterfaceKind::ModelExchange => self.model_exchange.as_ref(),
        }
    }

    /// Names close to `name`, for "did you mean" in messages: the same
    /// name in other case, names that contain it (or that it contains, if
    /// they are not tiny), and names at most two edits away.
    pub fn similar_names(&self, name: &str) -> Vec<&str> {
        let wanted = name.to_lowercase();
        self.variables
            .iter()
            .map(|v| v.name.as_str())
            .filter(|candidate| {
                let candidate = candidate.to_lowercase();
                let contains = (candidate.len() >= 3 && wanted.contains(&candidate))
                    || (wanted.len() >= 3 && candidate.contains(&wanted));
                contains || edit_distance(&candidate, &wanted) <= 2.min(wanted.len() / 3)
            })
            .take(5)
            .collect()
    }
}

/// The Levenshtein distance between two strings, by characters.
fn edit_distance(a: &str, b: &str) -> usize {
    let b: Vec<char> = b.chars().collect();
    let mut row: Vec<usize> = (0..=b.len()).collect();
    for (i, ca) in a.chars().enumerate() {
        let mut diagonal = row[0];
        row[0] = i + 1;
        for (j, &cb) in b.iter().enumerate() {
            let substitution = diagonal + usize::from(ca != cb);
            diagonal = row[j + 1];
            row[j + 1] = substitution.min(row[j] + 1).min(diagonal + 1);
        }
    }
    row[b.len()]
}

/// Reads elements and builds errors with their lines.
struct Reader<'d, 'input> {
    doc: &'d roxmltree::Document<'input>,
    path: &'d str,
}

impl Reader<'_, '_> {
    fn line(&self, node: roxmltree::Node<'_, '_>) -> usize {
        self.doc.text_pos_at(node.range().start).row as usize
    }

    fn error(&self, node: roxmltree::Node<'_, '_>, message: String) -> FmiError {
        FmiError::Description {
            path: self.path.into(),
            line: Some(self.line(node)),
            message,
        }
    }

    fn required<'a>(&self, node: roxmltree::Node<'a, '_>, key: &str) -> Result<&'a str> {
        node.attribute(key).ok_or_else(|| {
            self.error(
                node,
                format!("<{}> lacks the attribute {key}", node.tag_name().name()),
            )
        })
    }

    fn flag(&self, node: roxmltree::Node<'_, '_>, key: &str) -> Result<bool> {
        match node.attribute(key) {
            None | Some("false") | Some("0") => Ok(false),
            Some("true") | Some("1") => Ok(true),
            Some(other) => Err(self.error(
                node,
                format!("{key}=\"{other}\" is not a boolean (true or false)"),
            )),
        }
    }

    fn number(&self, node: roxmltree::Node<'_, '_>, key: &str) -> Result<Option<f64>> {
        node.attribute(key)
            .map(|text| {
                text.trim()
                    .parse::<f64>()
                    .map_err(|_| self.error(node, format!("{key}=\"{text}\" is not a number")))
            })
            .transpose()
    }

    fn count(&self, node: roxmltree::Node<'_, '_>, key: &str) -> Result<usize> {
        node.attribute(key).map_or(Ok(0), |text| {
            text.trim()
                .parse::<usize>()
                .map_err(|_| self.error(node, format!("{key}=\"{text}\" is not a count")))
        })
    }

    fn interface(&self, node: roxmltree::Node<'_, '_>, kind: InterfaceKind) -> Result<Interface> {
        Ok(Interface {
            kind,
            model_identifier: self.required(node, "modelIdentifier")?.to_string(),
            once_per_process: self.flag(node, "canBeInstantiatedOnlyOncePerProcess")?,
            needs_execution_tool: self.flag(node, "needsExecutionTool")?,
        })
    }

    /// The units of declared types, so that a variable that names its
    /// type gets the type's unit.
    fn declared_units(
        &self,
        root: roxmltree::Node<'_, '_>,
        version: FmiVersion,
    ) -> HashMap<String, String> {
        let mut units = HashMap::new();
        let Some(types) = root.children().find(|n| n.has_tag_name("TypeDefinitions")) else {
            return units;
        };
        for ty in types.children().filter(roxmltree::Node::is_element) {
            let (name, unit) = match version {
                FmiVersion::V2 => (
                    ty.attribute("name"),
                    ty.children()
                        .find(|n| n.has_tag_name("Real"))
                        .and_then(|r| r.attribute("unit")),
                ),
                FmiVersion::V3 => (ty.attribute("name"), ty.attribute("unit")),
            };
            if let (Some(name), Some(unit)) = (name, unit) {
                units.insert(name.to_string(), unit.to_string());
            }
        }
        units
    }

    fn variable(
        &self,
        node: roxmltree::Node<'_, '_>,
        version: FmiVersion,
        units: &HashMap<String, String>,
    ) -> Result<Variable> {
        let name = self.required(node, "name")?.to_string();
        let value_reference = self.required(node, "valueReference")?;
        let value_reference = value_reference.trim().parse::<u32>().map_err(|_| {
            self.error(
                node,
                format!("variable '{name}': valueReference=\"{value_reference}\" is not an unsigned 32-bit number"),
            )
        })?;
        let causality = match node.attribute("causality") {
            None => Causality::Local,
            Some(text) => Causality::parse(text).ok_or_else(|| {
                self.error(
                    node,
                    format!("variable '{name}': unknown causality \"{text}\""),
                )
            })?,
        };
        let variability = match node.attribute("variability") {
            None => Variability::Continuous,
            Some(text) => Variability::parse(text).ok_or_else(|| {
                self.error(
                    node,
                    format!("variable '{name}': unknown variability \"{text}\""),
                )
            })?,
        };
        // FMI 2.0 puts the type in a child element; FMI 3.0 is the element.
        let typed = match version {
            FmiVersion::V2 => node
                .children()
                .find(roxmltree::Node::is_element)
                .ok_or_else(|| {
                    self.error(
                        node,
                        format!("variable '{name}' has no type element (<Real/>, ...)"),
                    )
                })?,
            FmiVersion::V3 => node,
        };
        let type_name = typed.tag_name().name().to_string();
        let is_real_scalar = match version {
            FmiVersion::V2 => type_name == "Real",
            FmiVersion::V3 => {
                type_name == "Float64" && !node.children().any(|n| n.has_tag_name("Dimension"))
            }
        };
        let start = if is_real_scalar {
            self.number(typed, "start")?
        } else {
            None
        };
        let unit = typed.attribute("unit").map(str::to_string).or_else(|| {
            typed
                .attribute("declaredType")
                .and_then(|t| units.get(t).cloned())
        });
        Ok(Variable {
            name,
            value_reference,
            causality,
            variability,
            is_real_scalar,
            type_name,
            start,
            unit,
            description: node.attribute("description").map(str::to_string),
            line: self.line(node),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const FMI3: &str = r#"<?xml version="1.0" encoding="UTF-8"?>
<fmiModelDescription fmiVersion="3.0" modelName="osc" instantiationToken="{abc}">
  <ModelExchange modelIdentifier="osc" canBeInstantiatedOnlyOncePerProcess="true"/>
  <TypeDefinitions><Float64Type name="Angle" unit="rad"/></TypeDefinitions>
  <DefaultExperiment stopTime="10" stepSize="0.01"/>
  <ModelVariables>
    <Float64 name="time" valueReference="0" causality="independent" variability="continuous"/>
    <Float64 name="phi" valueReference="1" declaredType="Angle" start="0.1"/>
    <Float64 name="der(phi)" valueReference="2" derivative="1"/>
    <Float64 name="table" valueReference="3" causality="parameter" variability="fixed" start="1 2">
      <Dimension start="2"/>
    </Float64>
    <Int32 name="n" valueReference="4" causality="parameter" variability="fixed" start="3"/>
  </ModelVariables>
  <ModelStructure>
    <ContinuousStateDerivative valueReference="2"/>
    <EventIndicator valueReference="1"/>
  </ModelStructure>
</fmiModelDescription>"#;

    #[test]
    fn reads_fmi3_variables_states_and_event_indicators() {
        let md = ModelDescription::parse(FMI3, "osc.fmu").unwrap();
        assert_eq!(md.version, FmiVersion::V3);
        assert_eq!(md.token, "{abc}");
        assert!(md.co_simulation.is_none());
        assert!(md.model_exchange.as_ref().unwrap().once_per_process);
        assert_eq!((md.continuous_states, md.event_indicators), (1, 1));
        let phi = md.variable("phi").unwrap();
        assert_eq!(phi.unit.as_deref(), Some("rad"), "the declared type's unit");
        assert_eq!(phi.causality, Causality::Local);
        assert_eq!(phi.variability, Variability::Continuous);
        assert_eq!(phi.line, 8);
        assert!(!md.variable("table").unwrap().is_real_scalar, "an array");
        assert!(!md.variable("n").unwrap().is_real_scalar, "an integer");
        assert_eq!(md.default_experiment.step_size, Some(0.01));
    }

    #[test]
    fn edit_distance_counts_insertions_deletions_and_substitutions() {
        assert_eq!(edit_distance("kitten", "sitting"), 3);
        assert_eq!(edit_distance("", "abc"), 3);
        assert_eq!(edit_distance("mass", "mass"), 0);
        assert_eq!(edit_distance("vehicle.mass", "vehicle.m4ss"), 1);
    }

    #[test]
    fn malformed_descriptions_name_the_line() {
        let err = ModelDescription::parse(
            &FMI3.replace(
                "valueReference=\"2\" derivative",
                "valueReference=\"-2\" derivative",
            ),
            "osc.fmu",
        )
        .unwrap_err();
        assert!(
            matches!(err, FmiError::Description { line: Some(9), .. }),
            "{err}"
        );
        assert!(err.to_string().contains("der(phi)"), "{err}");
        let err = ModelDescription::parse(
            "<fmiModelDescription fmiVersion=\"1.0\" modelName=\"x\"/>",
            "old.fmu",
        )
        .unwrap_err();
        assert!(matches!(err, FmiError::UnsupportedVersion { .. }), "{err}");
        let err = ModelDescription::parse("<fmiModelDescription", "cut.fmu").unwrap_err();
        assert!(err.to_string().contains("not well-formed"), "{err}");
        let err = ModelDescription::parse(&FMI3.replace("name=\"n\"", "name=\"phi\""), "osc.fmu")
            .unwrap_err();
        assert!(err.to_string().contains("used twice"), "{err}");
        let none = FMI3.replace(
            "<ModelExchange modelIdentifier=\"osc\" canBeInstantiatedOnlyOncePerProcess=\"true\"/>",
            "",
        );
        let err = ModelDescription::parse(&none, "osc.fmu").unwrap_err();
        assert!(err.to_string().contains("neither"), "{err}");
    }
}
