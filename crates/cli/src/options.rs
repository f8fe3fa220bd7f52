//! Options that several commands share, as enumerations clap checks and
//! lists in `--help`.

/// How a command prints its report: `--format text|json` on every command
/// that prints one (`--json` is kept as a hidden alias of `--format json`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, clap::ValueEnum)]
pub enum ReportFormat {
    /// For people.
    #[default]
    Text,
    /// For tools: the report as JSON.
    Json,
}

/// The report format options of a command.
#[derive(Debug, Clone, clap::Args)]
pub struct FormatArgs {
    /// Print the report as text or as JSON.
    #[arg(long, value_enum, default_value_t = ReportFormat::Text)]
    format: ReportFormat,
    /// The same as --format json.
    #[arg(long, hide = true, conflicts_with = "format")]
    json: bool,
}

impl FormatArgs {
    /// Whether the report is to be JSON.
    pub fn json(&self) -> bool {
        self.json || self.format == ReportFormat::Json
    }
}

/// How `estimate` writes its table of estimates.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, clap::ValueEnum)]
pub enum TableFormat {
    /// One row per record, comma separated.
    #[default]
    Csv,
    /// An array of objects, one per record.
    Json,
}

/// The initial covariance of the Kalman filters' parameter state, as the
/// paper's equations give it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, clap::ValueEnum)]
pub enum InitialCovariance {
    /// Eq. (6): a large initial variance.
    #[default]
    Eq6,
    /// Eq. (7): a small initial variance.
    Eq7,
}

impl From<InitialCovariance> for twostage::baselines::InitialCovariance {
    fn from(p0: InitialCovariance) -> Self {
        match p0 {
            InitialCovariance::Eq6 => Self::Eq6,
            InitialCovariance::Eq7 => Self::Eq7,
        }
    }
}
