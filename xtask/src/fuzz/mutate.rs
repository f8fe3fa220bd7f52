//! One input of the fuzzer: a corpus entry mutated as the execution's
//! random bytes decide, read through `arbitrary::Unstructured`.

use arbitrary::{Result, Unstructured};

/// Bytes that sit at the edges of what readers accept.
const INTERESTING_BYTES: [u8; 10] = [0, 1, 0x7f, 0x80, 0xff, b'\n', b',', b'"', b'=', b'['];

/// Integers a length, a count or an index read from a file might be.
const INTERESTING_WORDS: [u64; 12] = [
    0,
    1,
    2,
    0x7f,
    0xff,
    0xffff,
    0x7fff_ffff,
    0xffff_ffff,
    0x1_0000_0000,
    1 << 40,
    i64::MAX as u64,
    u64::MAX,
];

/// What a number or a word in a text file might be replaced by.
const HOSTILE_TOKENS: [&str; 22] = [
    "0",
    "-0",
    "-1",
    "1e308",
    "-1e308",
    "1e-320",
    "NaN",
    "inf",
    "-inf",
    "1000000000000",
    "18446744073709551616",
    "99999999999999999999999999",
    "0.0000000000000000000001",
    "",
    "\"\"",
    "[]",
    "{}",
    "((((((((((x))))))))))",
    "x+x+x+x+x+x+x+x+x+x+x+x",
    "1/0",
    "\u{0}",
    "\u{feff}",
];

/// How many mutations one input gets at most.
const MOST_MUTATIONS: u32 = 8;

/// Mutate `input` in place; `other` is another corpus entry for splicing,
/// `text` whether the reader reads text (tokens are then swapped whole).
pub(super) fn mutate(
    u: &mut Unstructured<'_>,
    input: &mut Vec<u8>,
    other: &[u8],
    text: bool,
) -> Result<()> {
    let count = u.int_in_range(1..=MOST_MUTATIONS)?;
    for _ in 0..count {
        let kind = u.int_in_range(0..=9)?;
        match kind {
            0 => flip_bit(u, input)?,
            1 => set_byte(u, input)?,
            2 => set_word(u, input)?,
            3 => insert_bytes(u, input)?,
            4 => delete_range(u, input)?,
            5 => repeat_range(u, input)?,
            6 => splice(u, input, other)?,
            7 => truncate(u, input)?,
            _ if text => swap_token(u, input)?,
            _ => set_word(u, input)?,
        }
    }
    Ok(())
}

/// A position in `0..len` (0 when empty).
fn position(u: &mut Unstructured<'_>, len: usize) -> Result<usize> {
    if len == 0 {
        Ok(0)
    } else {
        u.int_in_range(0..=len - 1)
    }
}

/// A range inside `0..len`, at most `longest` long.
fn range(u: &mut Unstructured<'_>, len: usize, longest: usize) -> Result<std::ops::Range<usize>> {
    let start = position(u, len)?;
    let room = (len - start.min(len)).min(longest);
    let length = u.int_in_range(0..=room)?;
    Ok(start..start + length)
}

fn flip_bit(u: &mut Unstructured<'_>, input: &mut [u8]) -> Result<()> {
    if !input.is_empty() {
        let at = position(u, input.len())?;
        let bit = u.int_in_range(0..=7)?;
        if let Some(byte) = input.get_mut(at) {
            *byte ^= 1 << bit;
        }
    }
    Ok(())
}

fn set_byte(u: &mut Unstructured<'_>, input: &mut [u8]) -> Result<()> {
    let at = position(u, input.len())?;
    let value = *u.choose(&INTERESTING_BYTES)?;
    if let Some(byte) = input.get_mut(at) {
        *byte = value;
    }
    Ok(())
}

/// An interesting integer written little-endian over 1, 2, 4 or 8 bytes.
fn set_word(u: &mut Unstructured<'_>, input: &mut [u8]) -> Result<()> {
    let width = *u.choose(&[1usize, 2, 4, 8])?;
    let mut value = *u.choose(&INTERESTING_WORDS)?;
    if u.arbitrary::<bool>()? {
        value = value.wrapping_add(u.int_in_range(0..=16)?);
    }
    if input.len() >= width {
        let at = position(u, input.len() - width + 1)?;
        if let Some(slot) = input.get_mut(at..at + width) {
            slot.copy_from_slice(&value.to_le_bytes()[..width]);
        }
    }
    Ok(())
}

fn insert_bytes(u: &mut Unstructured<'_>, input: &mut Vec<u8>) -> Result<()> {
    let at = position(u, input.len() + 1)?;
    let count = u.int_in_range(1..=32)?;
    let mut bytes = Vec::with_capacity(count);
    for _ in 0..count {
        bytes.push(u.arbitrary::<u8>()?);
    }
    input.splice(at..at, bytes);
    Ok(())
}

fn delete_range(u: &mut Unstructured<'_>, input: &mut Vec<u8>) -> Result<()> {
    let cut = range(u, input.len(), 64)?;
    input.drain(cut);
    Ok(())
}

/// A range repeated in place up to 64 times (lists grown, depth nested).
fn repeat_range(u: &mut Unstructured<'_>, input: &mut Vec<u8>) -> Result<()> {
    let copy = range(u, input.len(), 64)?;
    let times = u.int_in_range(1..=64)?;
    let piece = input
        .get(copy.clone())
        .map(<[u8]>::to_vec)
        .unwrap_or_default();
    let repeated: Vec<u8> = std::iter::repeat_n(piece, times).flatten().collect();
    input.splice(copy.end..copy.end, repeated);
    Ok(())
}

/// A range of another corpus entry in place of a range of this one.
fn splice(u: &mut Unstructured<'_>, input: &mut Vec<u8>, other: &[u8]) -> Result<()> {
    let from = range(u, other.len(), 256)?;
    let to = range(u, input.len(), 256)?;
    let piece = other.get(from).map(<[u8]>::to_vec).unwrap_or_default();
    input.splice(to, piece);
    Ok(())
}

fn truncate(u: &mut Unstructured<'_>, input: &mut Vec<u8>) -> Result<()> {
    let keep = position(u, input.len() + 1)?;
    input.truncate(keep);
    Ok(())
}

/// A run of letters, digits and dots (a number or a name) replaced by a
/// hostile token.
fn swap_token(u: &mut Unstructured<'_>, input: &mut Vec<u8>) -> Result<()> {
    let token = |b: u8| b.is_ascii_alphanumeric() || b == b'.' || b == b'_' || b == b'-';
    let mut at = position(u, input.len())?;
    while at < input.len() && !input.get(at).copied().is_some_and(token) {
        at += 1;
    }
    while at > 0 && input.get(at - 1).copied().is_some_and(token) {
        at -= 1;
    }
    let mut end = at;
    while input.get(end).copied().is_some_and(token) {
        end += 1;
    }
    let with = *u.choose(&HOSTILE_TOKENS)?;
    input.splice(at..end, with.bytes());
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_same_bytes_make_the_same_input_and_others_differ() {
        let seed: Vec<u8> = (0..=255).collect();
        let make = |noise: &[u8]| {
            let mut input = b"a = 1\nb = [2, 3]\n".to_vec();
            mutate(&mut Unstructured::new(noise), &mut input, &seed, true).unwrap();
            input
        };
        let noise: Vec<u8> = (0..512u32).map(|i| (i * 37 % 251) as u8).collect();
        assert_eq!(make(&noise), make(&noise));
        let other: Vec<u8> = noise.iter().map(|b| b.wrapping_add(1)).collect();
        assert_ne!(make(&noise), make(&other));
    }

    #[test]
    fn a_token_is_swapped_whole() {
        let text = "x = 12.5e3\n";
        for k in 0..200u32 {
            let noise: Vec<u8> = (0..64u32).map(|i| (i * 13 + k * 101) as u8).collect();
            let mut input = text.as_bytes().to_vec();
            swap_token(&mut Unstructured::new(&noise), &mut input).unwrap();
            let out = String::from_utf8_lossy(&input).into_owned();
            // The name, the number, or (from the last byte) nothing is
            // replaced, each by one whole hostile token.
            let whole = HOSTILE_TOKENS.iter().any(|t| {
                out == format!("{t} = 12.5e3\n")
                    || out == format!("x = {t}\n")
                    || out == format!("{text}{t}")
            });
            assert!(whole, "{out:?}");
        }
    }
}
