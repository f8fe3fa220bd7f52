//! Where the records of a two-stage estimator's training come from, behind
//! one [`RecordSource`]: simulated on the fly (a built-in model, a model
//! file's command, an FMU), read from chart files (CSV or NumPy), or merged
//! from shards simulated on a cluster; and the formats these live in: the
//! model file ([`ModelFile`]), the chart folder ([`ChartFiles`]) and the
//! shard file ([`ShardedChart`]).
//!
//! Every source hands out the records of each [`ChartRole`] (training,
//! calibration, validation) compressed, in one order whatever the thread
//! count or shard split, so that the facade's one `train` never knows which
//! it reads.
//!
//! # Example
//!
//! ```
//! use twostage_compress::Arx;
//! use twostage_models::{Benchmark, Simulator};
//! use twostage_sources::{ChartRole, compress_chart};
//!
//! let model = Benchmark::builder().n_samples(200).build()?;
//! let design = ChartRole::Training.design(model.prior(), 50, 1)?;
//! let chart = compress_chart(&model, &Arx::new(2, 2)?, &design, "training", 0.0)?;
//! assert_eq!(chart.features.dim(), (50, 4));
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
#![deny(missing_docs)]

mod chart;
mod chart_arrays;
mod chart_file;
pub mod chart_writer;
pub mod csv_rows;
mod error;
mod model_file;
mod named_model;
pub mod parameter_values;
mod preset;
mod profile;
mod progress;
mod readable;
pub mod record_file;
mod records;
mod records_request;
mod roles;
mod shard;

pub use chart::ForModel;
pub use chart::{
    CompressedChart, ExperimentFailure, StoredChart, compress_chart, simulate_records,
};
pub use chart_arrays::ChartArrays;
pub use chart_file::ChartFiles;
pub use chart_writer::{CsvChart, write_csv_chart};
pub use error::{Error, InvalidSetting, Result};
pub use model_file::{
    CommandInput, DEFAULT_PRESET_SIMULATIONS, ModelFile, ModelSource, TEMPLATE, fmu_model_file,
};
pub use named_model::NamedModel;
pub use preset::Preset;
pub use profile::{
    ClassicMethod, ModelProfile, paper_benchmark, paper_pacejka, recommended_benchmark,
    recommended_pacejka,
};
pub use progress::{Progress, Silent, Stage};
pub use readable::refuse_beyond_memory;
pub use records::{RecordSource, Records, RunShape};
pub use records_request::{ChartDir, ChartGiven, RecordsRequest};
pub use roles::{ChartRole, RoleCounts};
pub use shard::{ShardIndex, ShardPlan, ShardedChart, fingerprint, simulate_shard};
pub use twostage_models::{available_memory, readable_bytes};
