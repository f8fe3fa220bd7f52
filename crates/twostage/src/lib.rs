//! Turn a simulator into an explicit, microsecond-fast parameter estimator.
//!
//! This is the two-stage (TS) method of Garatti and Bittanti ("A new
//! paradigm for parameter estimation in system modeling", Int. J. Adapt.
//! Control Signal Process., 2013):
//!
//! ```text
//! prior --simulate--> chart {theta_i, (u_i, y_i)} --compress g--> {theta_i, alpha_i} --fit h--> h
//! estimator f = clip_to_prior_box(h(g(u, y)))
//! ```
//!
//! Everything expensive happens once, offline, in [`TwoStage::train`]; an
//! estimate is then one small least-squares solve and one tiny network
//! evaluation ([`Estimator::estimate_into`]), with no iteration, no tuning
//! and no human in the loop. Training ends with calibration (conformal
//! intervals) and validation (the paper's Theorem 1) on fresh simulations.
//!
//! The pieces live in their own crates, re-exported here: [`models`]
//! (simulators), [`compress`] (stage 1), [`fit`] (stage 2), [`validate`],
//! [`sources`] (where records come from), [`estimator`] (the trained
//! estimator and its file), [`train`] (the builder and its run), [`auto`]
//! (the automatic design), [`refine`] (refinements and checks through a
//! model), [`baselines`] (the paper's competitors and the exact Bayes
//! references). This crate holds what every door (command line, Python,
//! shards) shares: the training request, the estimate request
//! ([`EstimateRequest`]), the validation run ([`validate_estimator`]), and
//! the policy that refines an estimator's estimates ([`EstimateRefiner`],
//! [`JointFitter`]).
//!
//! # Example
//!
//! ```
//! use twostage::TwoStage;
//! use twostage::models::{experiment_rng, Benchmark, Simulator};
//!
//! let model = Benchmark::new();
//! let estimator = TwoStage::builder(&model)
//!     .preset(twostage::paper_benchmark())
//!     .simulations(400)
//!     .validation(200)
//!     .calibration(200)
//!     .train()?;
//! let report = estimator.validation().expect("validated");
//! println!("{report}");
//! assert!(report.parameters[0].rmse < 0.3);
//!
//! // One estimate from a fresh record.
//! let mut record = model.spec().new_record();
//! model.simulate(&[-0.4], &mut experiment_rng(7, 0), &mut record)?;
//! let theta = estimator.estimate(record.input(0), record.output(0))?;
//! assert_eq!(theta.len(), 1);
//! # Ok::<(), twostage::Error>(())
//! ```
#![deny(missing_docs)]

mod request;
mod validation_run;

pub use request::{POSTERIOR_SHARE, Trained, TrainingRequest};
pub use twostage_auto::{
    AutoDesign, AutoOutcome, Budget, BudgetChoiceError, CandidateReport, FinalFit, FinalFits,
};
pub use twostage_compress::CompressorConfig;
pub use twostage_estimate::{
    AutoRefined, CheckSettings, EstimateRefiner, EstimateRequest, EstimateWith, Estimates,
    Estimating, EstimatorModel, GivenValues, GivenValuesError, JointFitter, JointOfRecords,
    JointRun, MethodFailure, ModelFailure, OUTPUT_ERROR_METHOD, OwnFit, Plant, PosteriorDraws,
    Purpose, RECORDS_TOGETHER, RecordBatch, RecordEstimate, RecordFailure, RecordOfJoint,
    RecordOutcome, RecordPlace, RefineChoiceError, RefineOutcome, RefineWhich, Refined, RefinedBy,
    RefinedEstimate, RegionValues, RequestError, RequestProblem, SearchOptima, SharedSimulator,
    ToRefine, Windows, draws_refused, fit_own_parameters, sharpen_refused, values_outside_prior,
};
pub use twostage_estimator::{
    AdaptiveIntervals, Assessment, ENVELOPE_LEVEL, EstimateWorkspace, Estimator, FORMAT_VERSION,
    FeatureEnvelope, FileError, MAGIC, RecordShape, SignalNames, TrainingInfo, check_writable,
    interval_in_box, write_whole,
};
pub use twostage_fit::{FittedRegressor, RegressorConfig};
pub use twostage_refine::{
    BestFit, CheckPlan, DEFAULT_CHECK_RUNS, Descent, EXPLAINED_LEVEL, LocalPosterior,
    LocalUncertainty, OutputError, RecordCheck, RefineError, RefinePolicy, RefineReason,
    RefineStarts, Refinement, ResidualModel, SearchStarts, WeightedMoments, check_against,
    check_record, check_with, output_fit, search_best_fits,
};
pub use twostage_setting::InvalidSetting;
pub use twostage_train::{DEFAULT_SEED, Error, Result, Run, RunSettings, TrainedOn, TwoStage};
pub use twostage_validate::CALIBRATION_DRAWS;
pub use validation_run::{
    TargetRmse, Validated, ValidationPlan, validate_estimator, validate_trained,
};

pub use twostage_sources::{
    ChartArrays, ChartDir, ChartFiles, ChartGiven, ChartRole, CompressedChart, ExperimentFailure,
    ModelFile, ModelSource, Preset, Progress, RecordSource, RecordsRequest, ShardIndex, ShardPlan,
    ShardedChart, Silent, Stage, TEMPLATE as MODEL_FILE_TEMPLATE, compress_chart, fingerprint,
    fmu_model_file, simulate_shard,
};
pub use twostage_sources::{
    ClassicMethod, ModelProfile, NamedModel, paper_benchmark, paper_pacejka, recommended_benchmark,
    recommended_pacejka,
};

pub use twostage_auto as auto;
pub use twostage_baselines as baselines;
pub use twostage_compress as compress;
pub use twostage_estimator as estimator;
pub use twostage_fit as fit;
pub use twostage_fmi as fmi;
pub use twostage_models as models;
pub use twostage_refine as refine;
pub use twostage_runtime as runtime;
pub use twostage_sources as sources;
pub use twostage_train as train;
pub use twostage_validate as validate;
