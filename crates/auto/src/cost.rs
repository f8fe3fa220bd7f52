//! What the search's fits cost, in one place: how a fit's time grows with
//! its network and its rows, the margins its estimates carry, and the
//! shares of the time left that its plans may spend. The measurements
//! behind every number are in docs/performance.md, "The automatic design's cost constants".

/// How a network's fit time grows with the cost of its Levenberg-Marquardt
/// products a row (`candidates::fit_cost`), for round 2's cost estimates
/// (see `round_two`): fit times grew as a power of the weights that was
/// 0.6 of the power the products grew by.
pub(crate) const PRODUCTS_EXPONENT: f64 = 0.6;
/// How a network's fit time grows with its rows: Levenberg-Marquardt's
/// products grow linearly with them, and its iterations to the held-out
/// minimum grow too (until its iteration limit). The upper end of what
/// the benchmark's fits measured, as fits that would not end in time cost
/// the whole final fit.
pub(crate) const ROWS_EXPONENT: f64 = 2.0;
/// Estimates of a fit's seconds carry a margin of a quarter: a fit that
/// would not end in time costs the whole fit.
pub(crate) const COST_MARGIN: f64 = 1.25;
/// Plans (round 2's rows, the final fit's records) spend at most this
/// share of the time they have: their costs are estimates.
pub(crate) const PLANNED_SHARE: f64 = 0.8;
/// The winner's refit keeps at most this share of the time left when
/// round 2 or 3 starts; the rounds get the rest.
pub(crate) const REFIT_SHARE: f64 = 0.45;
/// The share the final fit keeps instead, under a deadline, where a network
/// sized for a chart's records will compete in it: its members grow while
/// time is left, so the time pays there.
pub(crate) const SIZED_SHARE: f64 = 0.7;
/// Share of the time left before the winner's refit that round 3's
/// learned rival may spend on its network's epochs: the rest stays for
/// the final fit's further records, which it competes with.
pub(crate) const LEARNED_SHARE: f64 = 0.5;
/// A fit anew beside the fit trained further starts only if its estimate
/// is below this share of the time left.
pub(crate) const ANEW_SHARE: f64 = 0.9;

/// Fitting rows round 1 uses at most: it only picks the compressors worth
/// round 2, and the best few are close (the structures' scores differ far
/// less than round 2's networks move them); the time saved goes to round
/// 2 on every row.
pub(crate) const SCREENING_ROWS: usize = 4000;

/// Where the source can simulate more under a time budget, round 1 fits
/// half the screening rows: its ten fits only rank, and every second they
/// save buys records for the final fit (docs/accuracy.md measures both
/// ways on the car).
pub(crate) const QUICK_SCREEN_SHARE: f64 = 0.5;

/// Round 2 fits at least the full screening rows where round 1 on them
/// would have taken at most this share of the time the search had when
/// round 1 started: a structure that wins on many rows can lose on fewer
/// (the benchmark's 4 pieces of `[20]`, docs/accuracy.md). Round 1 on the
/// full rows is estimated from the quick round's time at
/// [`ROWS_EXPONENT`].
pub(crate) const SCREENING_TIME_SHARE: f64 = 0.5;

/// Round 1's rows out of `fit_rows`: the full screening rows (the user's
/// `asked` as set, else [`SCREENING_ROWS`], within the fitting rows), and
/// the rows round 1 fits: [`QUICK_SCREEN_SHARE`] of those where the source
/// `grows` and the user did not set them, else all of them.
pub(crate) fn screening_rows(asked: Option<usize>, fit_rows: usize, grows: bool) -> (usize, usize) {
    let full = asked.unwrap_or(SCREENING_ROWS).clamp(1, fit_rows.max(1));
    let quick = if asked.is_none() && grows {
        ((QUICK_SCREEN_SHARE * full as f64) as usize).max(1)
    } else {
        full
    };
    (full, quick)
}

/// The fewest rows round 2 fits: the `full` screening rows where round 1,
/// which took `seconds` on `screened` rows, would have taken at most
/// [`SCREENING_TIME_SHARE`] of the `left` seconds the search had when it
/// started had it fitted them, else round 1's rows.
pub(crate) fn round_two_floor((screened, seconds): (usize, f64), full: usize, left: f64) -> usize {
    if screened >= full || seconds * rows_growth(screened, full) <= SCREENING_TIME_SHARE * left {
        full.max(screened)
    } else {
        screened
    }
}

/// Relative score difference within which candidates count as tied, at
/// least (about what the seed alone moves a score by).
pub(crate) const MIN_TIE: f64 = 0.02;

/// Seconds to keep after the search for calibrating and validating on
/// `records` held-out records at `per_record` wall seconds each (a
/// simulation and its compression, or a read record's compression):
/// with a margin for the intervals' own fits.
pub(crate) fn held_out_seconds(per_record: f64, records: usize) -> f64 {
    1.2 * per_record * records as f64 + 1.0
}

/// Share of a time budget kept after the final fit on a chart read from
/// files, beside its held-out records' measured cost: the estimator's
/// envelope of the training features and the file are written then.
pub(crate) const CHART_FINISH_SHARE: f64 = 0.01;

/// How much longer a fit on `rows` rows takes than on `measured` rows.
pub(crate) fn rows_growth(measured: usize, rows: usize) -> f64 {
    (rows as f64 / measured.max(1) as f64).powf(ROWS_EXPONENT)
}

/// The seconds a fit on `rows` rows takes on the whole machine, from a
/// candidate's `seconds` on `measured` rows: with a margin of a quarter,
/// growing with the rows ([`ROWS_EXPONENT`]), and on the whole machine,
/// where the candidate shared it with the others of its round (each round
/// runs at least as many candidates as threads).
pub(crate) fn fit_seconds(seconds: f64, measured: usize, rows: usize) -> f64 {
    COST_MARGIN * seconds * rows_growth(measured, rows) / rayon::current_num_threads().max(1) as f64
}

/// Rows a round can fit on in `left` seconds when it costs `seconds` of
/// wall time on `screened` rows and grows with them as
/// [`ROWS_EXPONENT`] says: all `rows` if they fit, else as many as 80% of
/// the time affords (the costs are estimates), but never fewer than
/// `screened`.
pub(crate) fn affordable_rows(seconds: f64, left: f64, screened: usize, rows: usize) -> usize {
    if !(seconds.is_finite() && seconds > 0.0) {
        return rows;
    }
    let growth = (PLANNED_SHARE * left / seconds).max(0.0);
    let affordable = screened as f64 * growth.powf(1.0 / ROWS_EXPONENT);
    (affordable.min(usize::MAX as f64) as usize).clamp(screened.min(rows), rows)
}

/// The exponent of a fit's cost in its rows from two timings `(rows,
/// seconds)`, within the range the benchmark's fits measured (two
/// timings of one fit each are noisy).
pub(crate) fn measured_exponent(
    (rows_a, seconds_a): (usize, f64),
    (rows_b, seconds_b): (usize, f64),
) -> f64 {
    let exponent = (seconds_b / seconds_a).ln() / (rows_b as f64 / rows_a as f64).ln();
    if exponent.is_finite() {
        exponent.clamp(1.2, 2.2)
    } else {
        ROWS_EXPONENT
    }
}

/// Rows a final fit can take in `left` seconds, simulating each beyond
/// the chart's `chart_rows` in `per_simulation` seconds and fitting all in
/// `fit` seconds on `measured` rows, growing as rows^`exponent`: as many
/// as 80% of the time affords (the costs are estimates), between
/// `chart_rows` and `cap`.
pub(crate) fn rows_for_final_fit(
    left: f64,
    (per_simulation, fit, measured): (f64, f64, usize),
    exponent: f64,
    chart_rows: usize,
    cap: usize,
) -> usize {
    let cost = |rows: usize| {
        let growth = (rows as f64 / measured.max(1) as f64).powf(exponent);
        rows.saturating_sub(chart_rows) as f64 * per_simulation + fit * growth
    };
    let within = |rows: usize| cost(rows) <= PLANNED_SHARE * left;
    if !(per_simulation >= 0.0 && fit >= 0.0 && left.is_finite() && within(chart_rows)) {
        return chart_rows;
    }
    // The cost grows with the rows: bisect for the last affordable count.
    let (mut low, mut high) = (chart_rows, cap.max(chart_rows));
    if within(high) {
        return high;
    }
    while high - low > 1 {
        let middle = low + (high - low) / 2;
        if within(middle) {
            low = middle;
        } else {
            high = middle;
        }
    }
    low
}

/// The seconds a record added costs the final fit's steps: the slowest
/// pace yet, `pace` (`None` before any fit), or this fit's, which took
/// `seconds` for `added` records it had not trained on. A step whose fit
/// went on from a fit already near its minimum ends in a few iterations;
/// priced from it alone, the next step can double the records and be cut
/// by the deadline.
pub(crate) fn slowest_pace(pace: Option<f64>, seconds: f64, added: usize) -> f64 {
    let this = seconds / added.max(1) as f64;
    pace.map_or(this, |p| p.max(this))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Round 1 screens on 4000 rows at most, within the fitting rows, on
    /// what the user set where set, and quickly on half of them where the
    /// source grows.
    #[test]
    fn round_one_screens_quickly_where_the_source_grows() {
        assert_eq!(screening_rows(None, 2779, true), (2779, 1389));
        assert_eq!(screening_rows(None, 2779, false), (2779, 2779));
        assert_eq!(screening_rows(None, 6342, true), (4000, 2000));
        assert_eq!(screening_rows(None, 6342, false), (4000, 4000));
        assert_eq!(screening_rows(Some(100), 240, true), (100, 100));
        assert_eq!(screening_rows(Some(5000), 240, false), (240, 240));
        assert_eq!(screening_rows(None, 1, true), (1, 1));
        assert_eq!(screening_rows(None, 0, true), (1, 1));
    }

    /// Round 2 goes back to the full screening rows where round 1 on them
    /// would have kept within its share of the search, not otherwise.
    #[test]
    fn round_two_fits_the_full_screening_rows_where_round_one_was_cheap() {
        // 10 s on 2000 rows: 4000 would have taken 10 * 2^ROWS_EXPONENT.
        let full_cost = 10.0 * 2f64.powf(ROWS_EXPONENT);
        let left = full_cost / SCREENING_TIME_SHARE;
        assert_eq!(round_two_floor((2000, 10.0), 4000, 1.01 * left), 4000);
        assert_eq!(round_two_floor((2000, 10.0), 4000, 0.99 * left), 2000);
        // The benchmark's and the car's measured cases.
        assert_eq!(round_two_floor((2000, 11.2), 4000, 118.0), 4000);
        assert_eq!(round_two_floor((1389, 8.0), 2779, 45.5), 1389);
        // Nothing was screened: the floor is round 1's rows.
        assert_eq!(round_two_floor((4000, 1e9), 4000, 1.0), 4000);
        assert_eq!(round_two_floor((2000, 10.0), 4000, f64::NAN), 2000);
    }

    /// Round 2 fits every row when it can, as many as the time affords when
    /// it cannot, and never fewer than round 1 screened.
    #[test]
    fn round_two_takes_the_rows_its_time_affords() {
        // Twice the rows take 2^ROWS_EXPONENT times as long: 100 s on 4000
        // rows, so 8000 rows in 80% of `twice`.
        let twice = 100.0 * 2f64.powf(ROWS_EXPONENT) / PLANNED_SHARE;
        assert!(affordable_rows(100.0, twice, 4000, 32000).abs_diff(8000) <= 1);
        assert_eq!(affordable_rows(100.0, 2.0 * twice, 4000, 6000), 6000);
        assert_eq!(affordable_rows(100.0, 10.0, 4000, 32000), 4000);
        assert_eq!(affordable_rows(100.0, -5.0, 4000, 32000), 4000);
        // Round 1 fitted every row already: nothing more to take.
        assert_eq!(affordable_rows(100.0, 10.0, 240, 240), 240);
        assert_eq!(affordable_rows(0.0, 10.0, 4000, 32000), 32000);
        // A fit on twice the rows, on the whole machine, with a margin.
        let threads = rayon::current_num_threads() as f64;
        let expected = COST_MARGIN * 10.0 * 2f64.powf(ROWS_EXPONENT) / threads;
        assert!((fit_seconds(10.0, 4000, 8000) - expected).abs() < 1e-12);
    }

    /// The final fit takes the rows its time affords, simulations
    /// included, between the chart's and the cap.
    #[test]
    fn the_final_fit_takes_the_rows_its_time_affords() {
        // No simulation cost: the fit alone, as for round 2.
        let fit = 10.0;
        let twice = fit * 2f64.powf(ROWS_EXPONENT) / PLANNED_SHARE;
        let rows = rows_for_final_fit(twice, (0.0, fit, 4000), ROWS_EXPONENT, 4000, 32000);
        assert!(rows.abs_diff(8000) <= 1, "{rows}");
        // 1 ms per simulation on top: 4000 more rows cost 4 s more.
        let rows = rows_for_final_fit(
            twice + 4.0 / PLANNED_SHARE,
            (1e-3, fit, 4000),
            ROWS_EXPONENT,
            4000,
            32000,
        );
        assert!(rows.abs_diff(8000) <= 1, "{rows}");
        assert_eq!(
            rows_for_final_fit(1e6, (1e-3, fit, 4000), ROWS_EXPONENT, 4000, 16000),
            16000
        );
        // Not even the chart's rows fit: the chart's, no more.
        assert_eq!(
            rows_for_final_fit(1.0, (1e-3, fit, 4000), ROWS_EXPONENT, 4000, 16000),
            4000
        );
        // Grown as rows^1.5: 1.6 times the rows for 1.6^1.5 the time.
        let grown = fit * 1.6f64.powf(1.5) / PLANNED_SHARE;
        let rows = rows_for_final_fit(grown, (0.0, fit, 4000), 1.5, 4000, 32000);
        assert!(rows.abs_diff(6400) <= 1, "{rows}");
        assert!((measured_exponent((2000, 1.0), (4000, 4.0)) - 2.0).abs() < 1e-12);
        assert!((measured_exponent((2000, 1.0), (4000, 2.0f64.powf(1.5))) - 1.5).abs() < 1e-12);
        assert!((measured_exponent((2000, 1.0), (4000, 1.0)) - 1.2).abs() < 1e-12);
        assert!((measured_exponent((2000, 1.0), (4000, 100.0)) - 2.2).abs() < 1e-12);
        assert!((measured_exponent((2000, 0.0), (4000, 0.0)) - ROWS_EXPONENT).abs() < 1e-12);
        assert_eq!(
            rows_for_final_fit(f64::INFINITY, (1e-3, fit, 80), ROWS_EXPONENT, 80, 320),
            80
        );
    }

    #[test]
    fn the_pace_of_a_record_added_is_the_slowest_seen() {
        // The first fit's own: 12 s for 3000 records added.
        assert_eq!(slowest_pace(None, 12.0, 3000).to_bits(), 0.004f64.to_bits());
        // A step that ended in a few iterations leaves the pace as it was.
        assert_eq!(
            slowest_pace(Some(0.004), 2.0, 4000).to_bits(),
            0.004f64.to_bits()
        );
        // A slower one sets it.
        assert_eq!(
            slowest_pace(Some(0.004), 30.0, 5000).to_bits(),
            0.006f64.to_bits()
        );
        // No record added counts as one, not as a division by zero.
        assert_eq!(slowest_pace(None, 0.5, 0).to_bits(), 0.5f64.to_bits());
    }
}
