//! Where an estimator's training records came from, as one line of its
//! file says it: the design that drew their parameters, or the chart they
//! were read from. Written and read here, so no caller tells the two apart
//! by the text's first words.

use crate::Sampling;

/// How the line begins where the records were read from a chart.
const CHART_WORDS: &str = "the chart";

/// Where a training's records came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RecordsOrigin<'a> {
    /// Simulated, their parameters drawn by this design.
    Drawn(Sampling),
    /// Read from a chart: its description (files, and where the
    /// calibration and validation records came from).
    Chart(&'a str),
    /// A line this version does not know (kept as it is).
    Other(&'a str),
}

impl<'a> RecordsOrigin<'a> {
    /// The origin a stored line says.
    ///
    /// ```
    /// use twostage_models::{RecordsOrigin, Sampling};
    /// let chart = RecordsOrigin::Chart("runs/ (calibration: none; validation: none)");
    /// assert_eq!(RecordsOrigin::read(&chart.line()), chart);
    /// assert_eq!(RecordsOrigin::read("Sobol"), RecordsOrigin::Drawn(Sampling::Sobol));
    /// assert_eq!(RecordsOrigin::Drawn(Sampling::Uniform).line(), "Uniform");
    /// assert_eq!(RecordsOrigin::read("Sobol").to_string(), "simulated, Sobol design");
    /// assert_eq!(RecordsOrigin::read("Halton"), RecordsOrigin::Other("Halton"));
    /// ```
    pub fn read(line: &'a str) -> Self {
        if let Some(rest) = line.strip_prefix(CHART_WORDS) {
            return Self::Chart(rest.trim_start());
        }
        [Sampling::Uniform, Sampling::LatinHypercube, Sampling::Sobol]
            .into_iter()
            .find(|s| s.name() == line)
            .map_or(Self::Other(line), Self::Drawn)
    }

    /// The line that stores this origin.
    pub fn line(&self) -> String {
        match self {
            Self::Drawn(sampling) => sampling.name().to_string(),
            Self::Chart(chart) => format!("{CHART_WORDS} {chart}"),
            Self::Other(line) => (*line).to_string(),
        }
    }
}

impl std::fmt::Display for RecordsOrigin<'_> {
    /// In words: "the chart runs/ (...)", "simulated, Sobol design".
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Drawn(sampling) => write!(f, "simulated, {sampling} design"),
            Self::Chart(_) => f.write_str(&self.line()),
            Self::Other(line) => write!(f, "simulated, {line} design"),
        }
    }
}
