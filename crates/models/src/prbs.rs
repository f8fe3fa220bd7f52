//! Maximal-length linear feedback shift registers: the taps of the
//! pseudo-random binary sequences an input design draws.

/// Feedback taps of maximal-length linear feedback shift registers,
/// orders 2 to 20 (Xilinx application note XAPP 052, table 3: each a
/// primitive polynomial).
const PRBS_TAPS: [(u32, u32); 19] = [
    (2, 1),
    (3, 2),
    (4, 3),
    (5, 3),
    (6, 5),
    (7, 6),
    (8, 6),
    (9, 5),
    (10, 7),
    (11, 9),
    (12, 6),
    (13, 4),
    (14, 5),
    (15, 14),
    (16, 15),
    (17, 14),
    (18, 11),
    (19, 6),
    (20, 17),
];

/// The extra taps of the orders whose maximal register needs four
/// (XAPP 052): order, and its two further taps.
const PRBS_FOUR_TAPS: [(u32, u32, u32); 6] = [
    (8, 5, 4),
    (12, 4, 1),
    (13, 3, 1),
    (14, 3, 1),
    (16, 13, 4),
    (19, 2, 1),
];

/// The largest PRBS register order.
pub const MAX_PRBS_ORDER: u32 = 20;

/// The taps (counted from 1, the register's first bit) of the maximal
/// register of `order` bits.
pub(crate) fn prbs_taps(order: u32) -> Vec<u32> {
    let second = PRBS_TAPS
        .iter()
        .find(|(o, _)| *o == order)
        .map_or(1, |(_, t)| *t);
    let mut taps = vec![order, second];
    if let Some((_, a, b)) = PRBS_FOUR_TAPS.iter().find(|(o, _, _)| *o == order) {
        taps.extend([*a, *b]);
    }
    taps
}
