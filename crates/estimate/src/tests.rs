#![allow(clippy::unwrap_used)]
use super::*;
use twostage_models::Benchmark;
use twostage_train::TwoStage;

/// The same object behind two references to simulators.
fn same(a: &dyn Simulator, b: &dyn Simulator) -> bool {
    std::ptr::addr_eq(a as *const dyn Simulator, b as *const dyn Simulator)
}

/// A check, an output-error refinement and a joint fit run one
/// simulator, built once; a request of the output-error method shares
/// its simulator with its check.
#[test]
fn one_simulator_serves_the_check_the_refinement_and_the_joint_fit() {
    let estimator = TwoStage::builder(&Benchmark::new())
        .preset(twostage_sources::paper_benchmark())
        .simulations(300)
        .validation(0)
        .calibration(150)
        .seed(5)
        .train()
        .unwrap();
    let benchmark = || Some(NamedModel::builtin("benchmark").unwrap());
    let estimating = EstimateRequest::new(EstimateWith::Estimator(Box::new(estimator)))
        // Named, the built-in model is refined by output error.
        .model(benchmark())
        .check_records(true)
        .refine(Some(RefineWhich::All))
        .joint(true)
        .prepare()
        .unwrap();
    let checker = estimating.check_model().unwrap();
    let refiner = estimating.refiner.as_ref().unwrap().simulator().unwrap();
    let joint = estimating.joint.as_ref().unwrap().simulator();
    assert!(same(checker, refiner) && same(checker, joint));
    let fit = EstimateRequest::new(EstimateWith::OutputError { starts: 2 })
        .model(benchmark())
        .check_records(true)
        .prepare()
        .unwrap();
    let Method::OutputError(method) = &fit.method else {
        panic!("the output-error method");
    };
    assert!(same(
        fit.check_model().unwrap(),
        method.model().simulator().as_ref()
    ));
}
