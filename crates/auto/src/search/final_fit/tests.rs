// A panic is how a test fails.
#![allow(clippy::unwrap_used)]

use std::time::{Duration, Instant};

use ndarray::Array2;
use twostage_compress::{Arx, CompressorConfig};
use twostage_fit::{MlpParams, RegressorConfig};
use twostage_models::{Benchmark, Simulator};
use twostage_sources::{ForModel, StoredChart};
use twostage_train::TwoStage;

use super::super::{Candidate, Scope, Search};
use crate::candidates::{network, pieces};
use crate::{Budget, CandidateReport, Status};

/// A scored candidate of `net` on `compressor` at 4000 rows.
fn scored(
    compressor: &CompressorConfig,
    net: RegressorConfig,
    score: f64,
    seconds: f64,
) -> Candidate {
    // Any fit will do: the choice reads the reports and the networks.
    let x = Array2::from_shape_fn((40, 2), |(i, j)| ((i * 7 + j * 3) % 11) as f64);
    let y = Array2::from_shape_fn((40, 1), |(i, _)| (i % 5) as f64);
    let tiny = RegressorConfig::Mlp(MlpParams::new(&[2]).unwrap().check().unwrap());
    let fitted = tiny.fit(x.view(), y.view(), 1).unwrap();
    Candidate {
        report: CandidateReport {
            compressor: compressor.to_string(),
            regressor: String::new(),
            design: String::new(),
            round: 2,
            rmse: vec![score],
            score,
            seconds,
            fit_rows: 4000,
            status: Status::Scored,
            trained_by: None,
        },
        network: net,
        fitted: Some((compressor.clone(), fitted)),
        solo_seconds: None,
    }
}

/// ARX(NA, NA) prepared for the benchmark of [`with_search`].
fn arx_of(order: usize) -> CompressorConfig {
    let model = Benchmark::builder().n_samples(100).build().unwrap();
    CompressorConfig::from(Arx::new(order, order).unwrap())
        .for_model(model.spec())
        .unwrap()
}

/// `check` given a search over the benchmark whose candidates it sets
/// (nothing is fitted), with no deadline in sight, and ARX(2, 2);
/// `grows`: whether its source simulates.
fn with_search(grows: bool, check: impl FnOnce(&mut Search<'_, '_, Benchmark>, CompressorConfig)) {
    with_search_of(grows, 60, check);
}

/// [`with_search`] on a chart of `rows` records.
fn with_search_of(
    grows: bool,
    rows: usize,
    check: impl FnOnce(&mut Search<'_, '_, Benchmark>, CompressorConfig),
) {
    let far = Instant::now() + Duration::from_secs(1_000_000);
    with_search_under((Budget::Seconds(1e6), Some(far)), grows, rows, check);
}

/// [`with_search_of`] under `budget` and `deadline`.
fn with_search_under(
    (budget, deadline): (Budget, Option<Instant>),
    grows: bool,
    rows: usize,
    check: impl FnOnce(&mut Search<'_, '_, Benchmark>, CompressorConfig),
) {
    let model = Benchmark::builder().n_samples(100).build().unwrap();
    let run = TwoStage::builder(&model).simulations(60).prepare().unwrap();
    let chart = StoredChart {
        thetas: Array2::zeros((rows, 1)),
        records: Vec::new(),
    };
    let scope = Scope::of(&run);
    let mut search = Search::new(
        &scope,
        &chart,
        (budget, Instant::now(), deadline),
        Some(4000),
        grows,
    );
    check(&mut search, arx_of(2));
}

/// The car at 60 s, seed 3, two parameters: [20, 20] best
/// by 0.2% over [20] at 4.6 times its cost; [10] cheapest and within 2%
/// but worse than [20, 20] on both; [40] outside the tie.
fn car_tie(arx: &CompressorConfig) -> Vec<Candidate> {
    let net = |h: &[usize]| network(h).unwrap();
    let with_rmse = |mut c: Candidate, rmse: &[f64]| {
        c.report.rmse = rmse.to_vec();
        c
    };
    vec![
        with_rmse(
            scored(arx, net(&[20, 20]), 0.3637, 10.1),
            &[0.5413, 0.04202],
        ),
        with_rmse(scored(arx, net(&[20]), 0.3643, 2.2), &[0.5402, 0.04212]),
        with_rmse(scored(arx, net(&[10]), 0.3672, 0.8), &[0.5568, 0.04226]),
        with_rmse(scored(arx, net(&[40]), 0.3720, 0.5), &[0.5300, 0.04500]),
    ]
}

#[test]
fn on_a_chart_the_final_fit_keeps_only_what_its_held_out_records_cost() {
    let model = Benchmark::builder().n_samples(100).build().unwrap();
    let run = TwoStage::builder(&model).simulations(60).prepare().unwrap();
    let held_out = run.settings().calibration + run.settings().validation;
    let chart = StoredChart {
        thetas: Array2::zeros((60, 1)),
        records: Vec::new(),
    };
    let scope = Scope::of(&run);
    let start = Instant::now();
    let search_deadline = start + Duration::from_secs(95);
    let search_of = |grows| {
        Search::new(
            &scope,
            &chart,
            (Budget::Seconds(100.0), start, Some(search_deadline)),
            Some(4000),
            grows,
        )
    };
    // Read from files: 100 s less 1.2 x 10 us x the held-out records + 1 s,
    // less 1% of the budget.
    let read = search_of(false);
    let expected = 100.0 - (1.2 * 1e-5 * held_out as f64 + 1.0) - 1.0;
    let given = read
        .final_deadline(search_deadline, 1e-5)
        .duration_since(start)
        .as_secs_f64();
    assert!(
        (given - expected).abs() < 1e-6,
        "{given} against {expected}"
    );
    // Never earlier than the search's own deadline, however slow.
    assert_eq!(read.final_deadline(search_deadline, 1.0), search_deadline);
    // Simulated: the search's deadline already keeps their measured cost.
    let simulated = search_of(true);
    assert_eq!(
        simulated.final_deadline(search_deadline, 1e-5),
        search_deadline
    );
}

#[test]
fn the_rival_is_the_cheapest_larger_network_the_seed_could_have_ranked_first() {
    with_search(true, |search, arx| {
        let other = arx_of(3);
        let net = |h: &[usize]| network(h).unwrap();
        search.candidates = vec![
            scored(&arx, net(&[20]), 0.0428, 3.8),
            scored(&arx, net(&[40]), 0.0431, 13.2),
            scored(&arx, pieces(4, &[20]).unwrap(), 0.0436, 6.0),
            scored(&arx, net(&[20, 20]), 0.0431, 22.4),
            // Cheaper still, but not larger, or on another stage 1.
            scored(&arx, net(&[10]), 0.0430, 1.0),
            scored(&other, net(&[40]), 0.0420, 2.0),
        ];
        // Too few final rows for a larger network to pay: none.
        assert_eq!(search.larger_network(0, 15_999), None);
        // Pieces tie with the best larger network (within 2%) and cost
        // least: they compete.
        assert_eq!(search.larger_network(0, 16_000), Some(2));
        // A measured seed spread below 2% still ties them; outside the
        // tie, the best-scoring larger network.
        search.seed_spread = Some(0.005);
        assert_eq!(search.larger_network(0, 16_000), Some(2));
        search.candidates[2].report.score = 0.0445;
        assert_eq!(search.larger_network(0, 16_000), Some(1));
        // A wider seed spread ties them again.
        search.seed_spread = Some(0.04);
        assert_eq!(search.larger_network(0, 16_000), Some(2));
    });
}

#[test]
fn the_winner_is_the_cheapest_of_the_ties_that_no_candidate_beats_on_every_parameter() {
    with_search(true, |search, arx| {
        search.candidates = car_tie(&arx);
        let budget = Budget::Seconds(60.0);
        assert_eq!(search.best(&budget).unwrap(), 1);
        // A seed that moves scores by less than 2% still ties them; one
        // that moves them by 3% brings [40] in, now the cheapest.
        search.seed_spread = Some(0.001);
        assert_eq!(search.best(&budget).unwrap(), 1);
        search.seed_spread = Some(0.03);
        assert_eq!(search.best(&budget).unwrap(), 3);
        // Costlier than the best score: the best score wins.
        search.seed_spread = None;
        search.candidates[1].report.seconds = 12.0;
        assert_eq!(search.best(&budget).unwrap(), 0);
        // A time alone, where measured, says more than the round's shared
        // one: [20] cheap in round 2 but 20 s alone costs more than [20,
        // 20]'s shared 10.1 s on any number of threads.
        search.candidates[1].report.seconds = 2.2;
        assert_eq!(search.best(&budget).unwrap(), 1);
        search.candidates[1].solo_seconds = Some(20.0);
        assert_eq!(search.best(&budget).unwrap(), 0);
    });
}

#[test]
fn without_a_deadline_the_best_score_wins_whatever_the_times() {
    let budget = Budget::Simulations(60);
    with_search_under((budget, None), true, 60, |search, arx| {
        // The car's tie, where a deadline ships the cheaper [20] (above):
        // the times are measured, and must not choose what a seed fixes.
        search.candidates = car_tie(&arx);
        assert_eq!(search.best(&budget).unwrap(), 0);
        search.candidates[0].report.seconds = 0.1;
        search.candidates[1].solo_seconds = Some(0.01);
        search.seed_spread = Some(0.03);
        assert_eq!(search.best(&budget).unwrap(), 0);
    });
}

#[test]
fn with_one_parameter_the_best_score_wins_however_cheap_the_others() {
    with_search(true, |search, arx| {
        let net = |h: &[usize]| network(h).unwrap();
        search.candidates = vec![
            scored(&arx, net(&[10]), 0.0430, 1.0),
            scored(&arx, pieces(4, &[20]).unwrap(), 0.0423, 9.4),
            scored(&arx, net(&[20]), 0.0428, 6.9),
        ];
        assert_eq!(search.best(&Budget::Seconds(120.0)).unwrap(), 1);
    });
}

/// The sized ensemble grows a wave of one member a thread at a time
/// while a wave's time is left, to [`super::MAX_MEMBERS`], into the
/// fit of that many restarts at once; with less than a wave's time
/// left, it stays as fitted.
#[test]
fn the_sized_ensemble_grows_while_a_wave_of_members_fits_in_the_time_left() {
    let x = Array2::from_shape_fn((300, 2), |(i, j)| ((i * 13 + j * 5) % 41) as f64 / 20.0);
    let z = Array2::from_shape_fn((300, 1), |(i, _)| (x[[i, 0]] - x[[i, 1]]).sin());
    let ensemble = |members: usize| {
        let adam = twostage_fit::Trainer::Adam {
            learning_rate: 1e-2,
            batch_size: 50,
            epochs: 5,
        };
        RegressorConfig::Mlp(
            MlpParams::new(&[3])
                .unwrap()
                .ensemble(true)
                .trainer(adam)
                .restarts(members)
                .check()
                .unwrap(),
        )
    };
    let two_threads = rayon::ThreadPoolBuilder::new()
        .num_threads(2)
        .build()
        .unwrap();
    with_search(false, |search, _| {
        let seed = search.plan.base.seed();
        let four = ensemble(4).fit(x.view(), z.view(), seed).unwrap();
        let data = (x.view(), z.view());
        let far = Instant::now() + Duration::from_secs(3600);
        let (network, grown) = two_threads
            .install(|| search.more_members(ensemble(4), four.clone(), data, Duration::ZERO, far))
            .unwrap();
        assert_eq!(network, ensemble(16));
        assert_eq!(grown, ensemble(16).fit(x.view(), z.view(), seed).unwrap());
        // A wave takes half the first fit's 20 s (two rounds of two):
        // 11 s with the margin, more than the 10 s left.
        let near = Instant::now() + Duration::from_secs(10);
        let (network, kept) = two_threads
            .install(|| {
                search.more_members(
                    ensemble(4),
                    four.clone(),
                    data,
                    Duration::from_secs(20),
                    near,
                )
            })
            .unwrap();
        assert_eq!((network, kept), (ensemble(4), four));
    });
}

/// The rounds leave the final fit [`crate::cost::SIZED_SHARE`] of the
/// time where the sized network will compete: on a chart (not a
/// source that simulates) with records for it once the compared ones
/// are left out.
#[test]
fn the_sized_network_is_expected_on_a_chart_with_records_for_it() {
    let net = network(&[20]).unwrap();
    // ARX(2, 2) has 4 features: [32, 32] needs 1249 * 12 = 14,988
    // records, and the sized network at least 20,000.
    for (grows, rows, expected) in [
        (false, 22_000, true),
        (false, 21_999, false),
        (true, 22_000, false),
    ] {
        with_search_of(grows, rows, |search, arx| {
            search.candidates = vec![scored(&arx, net.clone(), 0.05, 1.0)];
            assert_eq!(
                search.sized_network_competes(0),
                expected,
                "{rows} rows, grows: {grows}"
            );
        });
    }
}

#[test]
fn a_network_sized_for_the_records_has_at_least_twelve_records_a_weight() {
    let widths = |rows, n, q| match super::network_for_rows(rows, n, q) {
        Some((RegressorConfig::Mlp(mlp), width)) => {
            assert_eq!(mlp.params().hidden(), [width, width]);
            assert!(mlp.params().is_ensemble(), "its restarts averaged");
            Some(mlp.params().hidden().to_vec())
        }
        _ => None,
    };
    // The predator-prey task: 40 features, 4 rates, 91,000 records.
    // [64, 64] has 41*64 + 65*64 + 65*4 = 7044 weights (7044 * 12 =
    // 84,528 records); [128, 128] 22,276.
    assert_eq!(widths(91_000, 40, 4), Some(vec![64, 64]));
    assert_eq!(widths(84_528, 40, 4), Some(vec![64, 64]));
    assert_eq!(widths(84_527, 40, 4), Some(vec![32, 32]));
    // The benchmark's 4 ARX coefficients: [32, 32] has 1249 weights,
    // [64, 64] 4545 (54,540 records).
    assert_eq!(widths(30_000, 4, 1), Some(vec![32, 32]));
    assert_eq!(widths(54_540, 4, 1), Some(vec![64, 64]));
    // Too few records, or too many features for even [32, 32].
    assert_eq!(widths(19_999, 4, 1), None);
    assert_eq!(widths(20_000, 200, 4), None);
}

#[test]
fn the_sized_network_competes_on_a_chart_where_larger_than_every_scored_one() {
    let net = |h: &[usize]| network(h).unwrap();
    let candidates = |arx: &CompressorConfig| {
        vec![
            scored(arx, net(&[20]), 0.0428, 3.8),
            scored(arx, net(&[40]), 0.0431, 13.2),
        ]
    };
    // A source that simulates spends the time on more records: the
    // larger candidate competes, trained further or anew.
    with_search(true, |search, arx| {
        search.candidates = candidates(&arx);
        assert!(matches!(
            search.rival(0, 32_000, 2000).map(|r| r.of),
            Some(super::RivalNetwork::Candidate(1))
        ));
    });
    // A chart cannot grow.
    with_search(false, |search, arx| {
        search.candidates = candidates(&arx);
        let hidden = |rival: Option<super::Rival>| {
            rival.map(|r| match (r.network, r.of) {
                (RegressorConfig::Mlp(mlp), of) => (mlp.params().hidden().to_vec(), of),
                (_, of) => (Vec::new(), of),
            })
        };
        // 30,000 records: [32, 32] (1249 weights) is larger than [40]
        // (241): it is the rival, fitted anew.
        assert_eq!(
            hidden(search.rival(0, 32_000, 2000)),
            Some((
                vec![32, 32],
                super::RivalNetwork::SizedForRows {
                    width: 32,
                    members: 4
                }
            ))
        );
        // A scored network larger still ([40, 40], 1881 weights) keeps
        // it out: a larger candidate competes instead (the cheapest of
        // the tied, [40]).
        search
            .candidates
            .push(scored(&arx, net(&[40, 40]), 0.0429, 30.0));
        assert_eq!(
            hidden(search.rival(0, 32_000, 2000)),
            Some((vec![40], super::RivalNetwork::Candidate(1)))
        );
        // Too few records compared: no rival at all.
        assert_eq!(hidden(search.rival(0, 32_000, 199)), None);
    });
}

/// The final fit trains the winner's scored fit further: a best-of-four
/// network goes on from its one kept restart, a quarter of a fit anew's
/// work, where an ensemble of four goes on with every member. At a cost
/// growing as rows^2 the same time affords the first twice the records.
#[test]
fn the_final_fit_plans_its_records_for_the_restarts_that_go_on() {
    let deadline = Instant::now() + Duration::from_secs(100);
    let threads = rayon::current_num_threads() as f64;
    // Seconds on 4000 rows such that 6000 rows of an ensemble trained
    // further take 80% of the 100 s left: 1.25 s (6000 / 4000)^2 / threads.
    let seconds = 0.8 * 100.0 * threads / (1.25 * 1.5 * 1.5);
    let planned = |net: RegressorConfig| {
        let mut rows = 0;
        with_search_under(
            (Budget::Seconds(100.0), Some(deadline)),
            true,
            4000,
            |search, arx| {
                search.candidates = vec![scored(&arx, net, 0.04, seconds)];
                rows = search.final_rows(0, true, 0.0, usize::MAX);
            },
        );
        rows as f64
    };
    let best_of_four = planned(network(&[20]).unwrap());
    let ensemble = RegressorConfig::Mlp(
        MlpParams::new(&[20])
            .unwrap()
            .ensemble(true)
            .check()
            .unwrap(),
    );
    let averaged = planned(ensemble);
    assert!((averaged / 6000.0 - 1.0).abs() < 0.01, "{averaged}");
    assert!(
        (best_of_four / 12_000.0 - 1.0).abs() < 0.01,
        "{best_of_four}"
    );
    // Pieces go on from their networks' kept restarts too.
    let pieces = planned(pieces(4, &[20]).unwrap());
    assert!((pieces / 12_000.0 - 1.0).abs() < 0.01, "{pieces}");
}

/// A learning curve's last step, projected: 0.045 on half the rows and
/// 0.0425 on all of them is a factor 0.0425 / 0.045 a doubling, so four
/// times the rows give 0.0425 (0.0425 / 0.045)^2; a curve that stopped
/// falling stays.
#[test]
fn a_score_is_projected_along_the_learning_curves_last_step() {
    let projected = super::super::equal_time::projected_score((0.045, 0.0425), 4.0);
    let by_hand = 0.0425 * (0.0425f64 / 0.045).powi(2);
    assert!(
        (projected - by_hand).abs() < 1e-15,
        "{projected} vs {by_hand}"
    );
    assert!((by_hand - 0.037_909).abs() < 1e-6);
    let stays =
        |half, factor| super::super::equal_time::projected_score((half, 0.0425), factor).to_bits();
    assert_eq!(stays(0.040, 4.0), 0.0425f64.to_bits());
    assert_eq!(stays(0.045, 1.0), 0.0425f64.to_bits());
}

/// An average of four [20, 20] that scores 0.0421 against the single
/// network's 0.0425, which scored 0.0451 on half its rows. Trained
/// further, the single network goes on from one restart, so in the
/// average's time it takes 4^(1/2) = 2 times the records (its cost as
/// rows^2), where its curve projects
/// 0.0425^2 / 0.0451 = 0.0400: it ships. An average that beats that
/// projection ships, and so does any average where the records cannot
/// grow.
#[test]
fn an_average_competes_with_its_single_network_at_equal_final_fit_time() {
    let deadline = Instant::now() + Duration::from_secs(100);
    let budget = Budget::Seconds(100.0);
    // The pick, and what the comparison said, for an average scoring
    // `score` where the records do or do not grow.
    let averaged = |score, grows| {
        let mut pick = usize::MAX;
        let mut told = None;
        with_search_under((budget, Some(deadline)), grows, 4000, |search, arx| {
            let ensemble = MlpParams::new(&[20, 20])
                .unwrap()
                .ensemble(true)
                .check()
                .unwrap();
            search.candidates = vec![
                scored(&arx, network(&[20, 20]).unwrap(), 0.0425, 17.4),
                scored(&arx, RegressorConfig::Mlp(ensemble), score, 9.3),
            ];
            search.averaged_twin = Some((0, 1));
            search.half_rows = Some((2000, 0.0451));
            pick = search.best(&budget).unwrap();
            told = search.equal_time(1);
        });
        (pick, told)
    };
    let (pick, told) = averaged(0.0421, true);
    assert_eq!(pick, 0);
    let told = told.unwrap();
    assert!((told.records_factor - 2.0).abs() < 1e-12);
    assert!((told.projected - 0.0425 * 0.0425 / 0.0451).abs() < 1e-12);
    assert_eq!(averaged(0.0395, true), (1, None));
    // On a chart that cannot grow the final fit takes no more records.
    assert_eq!(averaged(0.0421, false), (1, None));
}

/// Beside a larger network trained further, the winner's fit takes the
/// time in proportion to its cost: 4 s against 20 s is a sixth, so that
/// both go about as far; never less than a tenth nor more than a half.
#[test]
fn the_winner_and_a_larger_rival_share_the_time_as_their_costs_do() {
    assert!((super::winner_share(4.0, 20.0) - 1.0 / 6.0).abs() < 1e-12);
    assert!((super::winner_share(1.0, 99.0) - 0.1).abs() < 1e-12);
    assert!((super::winner_share(30.0, 20.0) - 0.5).abs() < 1e-12);
    assert!((super::winner_share(f64::NAN, 20.0) - 0.5).abs() < 1e-12);
    assert!((super::winner_share(0.0, 0.0) - 0.5).abs() < 1e-12);
}
