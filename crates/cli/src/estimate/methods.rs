//! The estimate request the command line's flags make: what estimates a
//! record (an estimator file, a classic method, the multi-start
//! output-error fit, or given values with `--at`), and the options each
//! reads.

use anyhow::Result;
use twostage::{
    CheckSettings, ClassicMethod, EstimateRequest, EstimateWith, Estimating, Estimator,
    OUTPUT_ERROR_METHOD, Purpose, RefineChoiceError, RefineWhich, RequestError, RequestProblem,
    Windows,
};

use super::EstimateArgs;
use crate::{UsageError, usage};

/// What `--method` names: a classic method of a built-in model, or the
/// multi-start output-error fit of any model.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum MethodChoice {
    Classic(ClassicMethod),
    OutputError,
}

impl MethodChoice {
    /// The method called `name` (as the help lists them).
    pub(super) fn parse(name: &str) -> std::result::Result<Self, String> {
        if name == OUTPUT_ERROR_METHOD {
            return Ok(Self::OutputError);
        }
        ClassicMethod::ALL
            .into_iter()
            .find(|m| m.name() == name)
            .map(Self::Classic)
            .ok_or_else(|| {
                let names: Vec<&str> = ClassicMethod::ALL
                    .iter()
                    .map(|m| m.name())
                    .chain([OUTPUT_ERROR_METHOD])
                    .collect();
                format!("'{name}': use one of {}", names.join(", "))
            })
    }

    /// Its name on the command line.
    fn name(self) -> &'static str {
        match self {
            Self::Classic(method) => method.name(),
            Self::OutputError => OUTPUT_ERROR_METHOD,
        }
    }
}

/// How the command line names the setting of a refusal of values outside
/// the prior (the request's words follow).
pub(crate) const OUTSIDE_PRIOR_FLAGS: &str = "--at without --allow-outside-prior";

/// Refuses an option that the chosen way of estimating would not read:
/// an option silently ignored reads as one that worked.
fn refuse_what_does_not_apply(args: &EstimateArgs, refine: Option<RefineWhich>) -> Result<()> {
    let checks = args.check || refine.is_some_and(RefineWhich::checks);
    let method = args.method;
    let running = match (method, &args.estimator, &args.at) {
        (Some(m), _, _) => format!("--method {}", m.name()),
        (None, Some(_), _) => "an estimator".to_string(),
        (None, None, Some(_)) => "--at".to_string(),
        (None, None, None) => return Ok(()),
    };
    use ClassicMethod::{Ekf, IndirectInference, ParticleFilter, PredictionError, Ukf};
    use MethodChoice::{Classic, OutputError};
    let filter = matches!(method, Some(Classic(Ekf | Ukf)));
    let particles = matches!(method, Some(Classic(ParticleFilter)));
    let multi_start = matches!(
        method,
        Some(Classic(PredictionError | IndirectInference) | OutputError)
    );
    let refuse = |option: &str, readers: &str| {
        Err(usage(format!(
            "{option} is read by {readers}; {running} does not read it: leave it out"
        )))
    };
    if (args.check_sims.is_some()
        || args.plot.is_some()
        || args.score_from.is_some()
        || args.score_to.is_some())
        && !checks
    {
        return refuse(
            "--check-sims, --plot, --score-from and --score-to",
            "--check and --refine=auto",
        );
    }
    match (&args.at, &args.estimator) {
        (Some(_), None) if !args.check => {
            return Err(usage(
                "--at checks given values with --check, or tests them against an estimator's \
                 posterior with --estimator and --samples: add one"
                    .into(),
            ));
        }
        (Some(_), Some(_)) if args.allow_outside_prior => {
            return Err(usage(
                "--allow-outside-prior goes with --at --check (values checked against the \
                 records); a posterior's draws lie inside the prior, and values outside it \
                 are in no region of it: leave it out"
                    .into(),
            ));
        }
        (Some(_), Some(_)) if args.samples.is_none() => {
            return Err(usage(
                "--at with an estimator tests the values against each record's posterior: \
                 add --samples N (its draws), or leave out --estimator and check the values \
                 with --check"
                    .into(),
            ));
        }
        _ => {}
    }
    if args.model.is_some() && method.is_none() && (args.at.is_none() || args.estimator.is_some()) {
        return refuse(
            "--model",
            "--method and --at (an estimator knows its model)",
        );
    }
    if args.correlation && args.refine.is_none() && !args.joint && args.samples.is_none() {
        return refuse("--correlation", "--refine, --joint and --samples");
    }
    if args.p0.is_some() && !filter {
        return refuse("--p0", "--method ekf and ukf");
    }
    if args.particles.is_some() && !particles {
        return refuse("--particles", "--method pf");
    }
    if args.starts.is_some() && !multi_start {
        return refuse("--starts", "--method pem, ii and oe");
    }
    let seeded = checks || args.joint || particles || multi_start || args.samples.is_some();
    if args.seed.is_some() && !seeded {
        return refuse(
            "--seed",
            "--method pf, pem, ii and oe, --check, --joint and --samples",
        );
    }
    Ok(())
}

/// The request the flags make, prepared: the model read once for every
/// use of it.
pub(super) fn prepared(args: &EstimateArgs) -> Result<Estimating> {
    let refine = RefineWhich::chosen(
        args.refine.map(|which| match which {
            super::RefineWhich::All => "all",
            super::RefineWhich::Auto => "auto",
        }),
        args.refine_below_fit,
    )
    .map_err(|e| match e {
        RefineChoiceError::BelowFitWithoutAuto => usage(format!("--refine-below-fit: {e}")),
        RefineChoiceError::Unknown(_) => usage(format!("--refine: {e}")),
    })?;
    refuse_what_does_not_apply(args, refine)?;
    // What a flag left out leaves to the methods' own defaults.
    let defaults = twostage::baselines::MethodSettings::default();
    let with = match (&args.estimator, &args.at, args.method) {
        (Some(path), _, _) => EstimateWith::Estimator(Box::new(Estimator::load(path)?)),
        (None, Some(path), _) => EstimateWith::GivenFile(path.clone()),
        (None, None, Some(MethodChoice::OutputError)) => EstimateWith::OutputError {
            starts: args.starts.unwrap_or(defaults.starts),
        },
        (None, None, Some(MethodChoice::Classic(method)))
            if args.model.is_some() || args.model_file.is_some() =>
        {
            EstimateWith::Classic {
                method,
                settings: twostage::baselines::MethodSettings {
                    initial_covariance: args.p0.map_or(defaults.initial_covariance, Into::into),
                    particles: args.particles,
                    starts: args.starts.unwrap_or(defaults.starts),
                    seed: args.seed.unwrap_or(defaults.seed),
                },
            }
        }
        _ => {
            return Err(usage(
                "give --estimator FILE, --model M --method ekf|ukf|pf|pem|ii|bayes, or --model \
                 M --at VALUES.csv --check"
                    .into(),
            ));
        }
    };
    let window = args.window.map(|length| Windows {
        length,
        every: args.every.unwrap_or(length),
    });
    // An empty window or step is refused by the request, said as --window.
    let request = EstimateRequest::new(with)
        .model(crate::model_arg::named(
            args.model.as_deref(),
            args.model_file.as_deref(),
        )?)
        .allow_outside_prior(args.allow_outside_prior)
        .check_records(args.check)
        .check_settings(CheckSettings {
            runs: args.check_sims.unwrap_or(twostage::DEFAULT_CHECK_RUNS),
            score_from: args.score_from.unwrap_or(0),
            score_to: args.score_to,
        })
        .refine(refine)
        .joint(args.joint)
        .windows(window)
        .seed(args.seed.unwrap_or(0))
        .samples(args.samples)
        .sharpen(args.sharpen)
        .region_at(
            args.estimator
                .as_ref()
                .and(args.at.clone())
                .map(twostage::RegionValues::File),
        )
        .prior_starts(args.prior_starts)
        .fix(
            twostage::models::FixedValues::parse(&args.fix)
                .map_err(|e| usage(format!("--fix: {e}")))?,
        );
    let estimating = request
        .prepare()
        .map_err(|e| said_as_the_flags_say_it(e, args))?;
    for note in estimating.notes() {
        eprintln!("note: {note}");
    }
    Ok(estimating)
}

/// A request's error in the words of the flag it came from.
fn said_as_the_flags_say_it(e: RequestError, args: &EstimateArgs) -> anyhow::Error {
    let flag = match e.purpose {
        Purpose::Method => format!("--method {}", args.method.map_or("", MethodChoice::name)),
        Purpose::OutputError => "--method oe".into(),
        Purpose::Given => "--at".into(),
        Purpose::Check => "--check".into(),
        Purpose::Refine => "--refine".into(),
        Purpose::Joint => "--joint".into(),
        Purpose::Windows => "--window".into(),
        Purpose::Samples => "--samples".into(),
        Purpose::Region => "--at".into(),
        Purpose::Fix => "--fix".into(),
        Purpose::Model if args.model_file.is_some() => "--model-file".into(),
        Purpose::Model => "--model".into(),
    };
    match e.error {
        RequestProblem::NoModel => usage(format!(
            "{flag} simulates the model: give --model M or --model-file F"
        )),
        RequestProblem::NotBuiltIn { .. } | RequestProblem::Values(_) => usage(e.error.to_string()),
        RequestProblem::OutsidePrior { .. } => usage(format!("{OUTSIDE_PRIOR_FLAGS}: {}", e.error)),
        // The method's own error names the method and the model.
        RequestProblem::Failed(cause) if e.purpose == Purpose::Method => {
            anyhow::Error::new(UsageError::Caused(cause))
        }
        // An estimator's model that cannot be run is said as the check's
        // need of it.
        RequestProblem::Failed(cause) if e.purpose == Purpose::Check => {
            anyhow::Error::from_boxed(cause)
                .context(UsageError::Said("--check simulates the model".into()))
        }
        RequestProblem::Failed(cause) => {
            anyhow::Error::from_boxed(cause).context(UsageError::Said(flag))
        }
        other => usage(format!("{flag}: {other}")),
    }
}
