//! A user's own model, end to end: a mass-spring-damper with unknown
//! stiffness k and damping c, implemented as a `Simulator`, turned into an
//! estimator, validated, saved, loaded and used.
//!
//! ```sh
//! cargo run --release -p twostage --example mass_spring_damper
//! ```
//!
//! The model: m x'' + c x' + k x = F(t), m = 1 kg, F a pseudo-random
//! sequence of force levels held for 0.5 s, x measured every 0.05 s with
//! Gaussian noise of standard deviation 1 mm. Unknown theta = (k, c) in
//! [20, 80] N/m x [0.5, 4] N s/m.

use rand::RngExt;
use rand_distr::{Distribution, Normal};
use twostage::compress::Arx;
use twostage::fit::MlpParams;
use twostage::models::{
    Conditions, ExperimentRng, IoData, ModelSpec, OdeSystem, Prior, Rk4, SimError, Simulator,
    experiment_rng,
};
use twostage::{Estimator, RegressorConfig, TwoStage};

const SAMPLE_TIME: f64 = 0.05;
const SAMPLES: usize = 400;
const STEPS_PER_SAMPLE: usize = 10;
const NOISE_SD: f64 = 1e-3;

/// The plant: state (x, v), force held constant over each sample.
struct Dynamics {
    stiffness: f64,
    damping: f64,
    force: f64,
}

impl OdeSystem for Dynamics {
    fn dim(&self) -> usize {
        2
    }
    fn rhs(&self, _t: f64, x: &[f64], dx: &mut [f64]) {
        dx[0] = x[1];
        dx[1] = self.force - self.damping * x[1] - self.stiffness * x[0];
    }
}

struct MassSpringDamper {
    spec: ModelSpec,
}

impl MassSpringDamper {
    fn new() -> Result<Self, SimError> {
        let prior = Prior::uniform_box(&[20.0, 0.5], &[80.0, 4.0])?;
        let spec = ModelSpec::new(
            "mass-spring-damper",
            &["k", "c"],
            prior,
            SAMPLE_TIME,
            SAMPLES,
        )?
        .with_signals(&["force"], &["position"])
        .with_notes(
            "random force levels in [-1, 1] N held for 0.5 s",
            "position noise sd 1 mm",
        );
        Ok(Self { spec })
    }
}

impl Simulator for MassSpringDamper {
    fn spec(&self) -> &ModelSpec {
        &self.spec
    }

    fn simulate_one(
        &self,
        theta: &[f64],
        rng: &mut ExperimentRng,
        _: Conditions<'_>,
        out: &mut IoData,
    ) -> Result<(), SimError> {
        self.spec
            .prior()
            .check(theta, self.spec.param_names(), true)?;
        out.resize(SAMPLES, 1, 1);
        let (u, y) = out.siso_mut();
        // The input: a new force level every 10 samples, drawn per experiment.
        for chunk in u.chunks_mut(10) {
            let level = rng.random_range(-1.0..1.0);
            chunk.fill(level);
        }
        let noise = Normal::new(0.0, NOISE_SD).map_err(|e| SimError::InvalidData(e.to_string()))?;
        let mut rk4 = Rk4::new(2);
        let mut x = [0.0f64; 2];
        let h = SAMPLE_TIME / STEPS_PER_SAMPLE as f64;
        for k in 0..SAMPLES {
            y[k] = x[0] + noise.sample(rng);
            let plant = Dynamics {
                stiffness: theta[0],
                damping: theta[1],
                force: u[k],
            };
            rk4.integrate(&plant, k as f64 * SAMPLE_TIME, h, STEPS_PER_SAMPLE, &mut x);
            if !x.iter().all(|v| v.is_finite()) {
                return Err(SimError::Diverged {
                    theta: theta.to_vec(),
                    time: (k + 1) as f64 * SAMPLE_TIME,
                });
            }
        }
        Ok(())
    }
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let plant = MassSpringDamper::new()?;
    // A second-order plant: ARX(2, 2) captures its dynamics; a small network
    // maps the coefficients back to (k, c).
    let start = std::time::Instant::now();
    let estimator = TwoStage::builder(&plant)
        .compressor(Arx::new(2, 2)?)
        .regressor(RegressorConfig::Mlp(MlpParams::new(&[12])?.check()?))
        .simulations(2000)
        .validation(500)
        .calibration(500)
        .seed(7)
        .train()?;
    println!("trained in {:.2} s", start.elapsed().as_secs_f64());
    if let Some(report) = estimator.validation() {
        println!("{report}");
    }
    let path = std::env::temp_dir().join("mass_spring_damper.tsest");
    estimator.save(&path)?;
    let loaded = Estimator::load(&path)?;
    // A "measured" record at k = 50 N/m, c = 1.5 N s/m.
    let mut record = plant.spec().new_record();
    plant.simulate(&[50.0, 1.5], &mut experiment_rng(123, 0), &mut record)?;
    let theta = loaded.estimate_record(&record)?;
    println!(
        "true (k, c) = (50, 1.5); estimated ({:.2}, {:.3})",
        theta[0], theta[1]
    );
    Ok(())
}
