//! Estimates the built-in records of each case with the runtime, sample by
//! sample as a control unit would, and prints over semihosting:
//!
//! - `calibration TICKS` for a loop of 300000 instructions (so the host
//!   converts SysTick ticks under `-icount` to instructions exactly);
//! - `case K blob BYTES workspace WORDS`;
//! - `record K R rc THETA.. WIDTHS.. OOD push TICKS finish TICKS` with
//!   every number as the hex bits of its f64;
//! - with the feature `window`: `window K length W workspace WORDS`, then,
//!   for a window of a quarter
//!   of a record slid over the case's records one after another and
//!   finished at each record's end, `slide K R rc THETA.. OOD MASK push
//!   TICKS finish TICKS` and the window's peak stack, `slide K stack
//!   BYTES`;
//! - with the feature `posterior`, after each record:
//!   `draws K R ok FIRST.. LAST.. finish TICKS`, the first eight numbers
//!   and the last draw of `DRAWS` draws of seed 1 and the record's number,
//!   and the ticks of the finish that drew them;
//! - then the peak stack of the records' estimates (`stack BYTES`) and the
//!   firmware's sections (`sections TEXT RODATA DATA BSS`).
#![no_std]
#![no_main]

use cortex_m::peripheral::{SYST, syst::SystClkSource};
use cortex_m_rt::entry;
use cortex_m_semihosting::{debug, hprintln};
use panic_semihosting as _;
#[cfg(not(feature = "baseline"))]
use twostage_runtime::{Estimator, Stream};

include!(concat!(env!("OUT_DIR"), "/cases.rs"));

/// The largest workspace a case may need, in f64 (32 KiB).
const WORK: usize = 4096;
static mut WORKSPACE: [f64; WORK] = [0.0; WORK];

/// Draws of each record, of at most two parameters.
#[cfg(feature = "posterior")]
const DRAWS: usize = 100;
#[cfg(feature = "posterior")]
static mut DRAWN: [f64; 2 * DRAWS] = [0.0; 2 * DRAWS];

const PAINT: u32 = 0xDEAD_BEEF;
/// How far below the stack pointer the paint goes.
const PAINTED: usize = 16 * 1024;

fn u32_at(bytes: &[u8], at: usize) -> usize {
    bytes
        .get(at..at + 4)
        .and_then(|b| b.try_into().ok())
        .map_or(0, |b| u32::from_le_bytes(b) as usize)
}

fn f64_at(bytes: &[u8], index: usize) -> f64 {
    bytes
        .get(16 + 8 * index..24 + 8 * index)
        .and_then(|b| b.try_into().ok())
        .map_or(f64::NAN, f64::from_le_bytes)
}

/// Ticks elapsed on the down-counting 24-bit SysTick since `start`.
fn since(start: u32) -> u32 {
    start.wrapping_sub(SYST::get_current()) & 0x00FF_FFFF
}

#[inline(never)]
fn spin(iterations: u32) {
    // 3 instructions per iteration: nop, subs, bne.
    unsafe {
        core::arch::asm!(
            "1:",
            "nop",
            "subs {0}, {0}, #1",
            "bne 1b",
            inout(reg) iterations => _,
        );
    }
}

/// Fill the stack below the current pointer with a pattern.
#[inline(never)]
fn paint() -> usize {
    let sp = cortex_m::register::msp::read() as usize;
    let bottom = sp - PAINTED;
    for a in (bottom..sp - 256).step_by(4) {
        unsafe { (a as *mut u32).write_volatile(PAINT) };
    }
    sp
}

/// Bytes of the painted stack that were written since `paint`.
fn used(sp: usize) -> usize {
    let bottom = sp - PAINTED;
    let untouched = (bottom..sp - 256)
        .step_by(4)
        .take_while(|a| unsafe { (*a as *const u32).read_volatile() } == PAINT)
        .count();
    PAINTED - 4 * untouched
}

#[entry]
fn main() -> ! {
    let mut peripherals = cortex_m::Peripherals::take().unwrap();
    let syst = &mut peripherals.SYST;
    syst.set_clock_source(SystClkSource::Core);
    syst.set_reload(0x00FF_FFFF);
    syst.clear_current();
    syst.enable_counter();

    let start = SYST::get_current();
    spin(100_000);
    hprintln!("calibration {}", since(start));

    let work = unsafe { &mut *core::ptr::addr_of_mut!(WORKSPACE) };
    let mut peak_stack = 0;
    for (k, (blob, records)) in CASES.iter().enumerate() {
        estimate_case(k, blob, records, work, &mut peak_stack);
    }
    hprintln!("stack {}", peak_stack);
    #[cfg(not(feature = "baseline"))]
    hprintln!("view {}", core::mem::size_of::<Estimator<'static>>());
    unsafe extern "C" {
        static __stext: u8;
        static __etext: u8;
        static __srodata: u8;
        static __erodata: u8;
        static __sdata: u8;
        static __edata: u8;
        static __sbss: u8;
        static __ebss: u8;
    }
    let span = |a: *const u8, b: *const u8| b as usize - a as usize;
    hprintln!(
        "sections {} {} {} {}",
        span(&raw const __stext, &raw const __etext),
        span(&raw const __srodata, &raw const __erodata),
        span(&raw const __sdata, &raw const __edata),
        span(&raw const __sbss, &raw const __ebss)
    );
    debug::exit(debug::EXIT_SUCCESS);
    loop {}
}

/// Estimate every record of one case and print the results.
#[cfg(not(feature = "baseline"))]
fn estimate_case(k: usize, blob: &[u8], records: &[u8], work: &mut [f64], peak_stack: &mut usize) {
    let estimator = match Estimator::from_bytes(blob) {
        Ok(e) => e,
        Err(e) => {
            hprintln!("case {} refused {}", k, e.code());
            return;
        }
    };
    hprintln!(
        "case {} blob {} workspace {}",
        k,
        blob.len(),
        estimator.workspace_len()
    );
    let count = u32_at(records, 0);
    let q = estimator.n_parameters();
    for r in 0..count {
        let sp = paint();
        let mut theta = [0.0; 8];
        let mut widths = [0.0; 8];
        let result = Stream::new(&estimator, work).and_then(|mut stream| {
            let push = push_record(&mut stream, records, r)?;
            let start = SYST::get_current();
            let assessment = stream.finish(&mut theta[..q], &mut widths[..q])?;
            Ok((assessment, push, since(start)))
        });
        *peak_stack = (*peak_stack).max(used(sp));
        match result {
            Ok((assessment, push, finish)) => {
                let mut line = heapless_line();
                for v in theta[..q].iter().chain(&widths[..q]) {
                    line.push_hex(v.to_bits());
                }
                hprintln!(
                    "record {} {} ok{} {} push {} finish {}",
                    k,
                    r,
                    line.as_str(),
                    u8::from(assessment.out_of_distribution()),
                    push,
                    finish
                );
            }
            Err(e) => hprintln!("record {} {} error {}", k, r, e.code()),
        }
        #[cfg(feature = "posterior")]
        draw(k, r, &estimator, records, work);
    }
    #[cfg(feature = "window")]
    slide(k, &estimator, records, work);
}

/// Push record `r` of `records` into `stream`, sample by sample; the
/// SysTick ticks it took.
#[cfg(not(feature = "baseline"))]
fn push_record(
    stream: &mut Stream<'_, '_, '_>,
    records: &[u8],
    r: usize,
) -> Result<u32, twostage_runtime::Error> {
    let (n, nu, ny) = (u32_at(records, 4), u32_at(records, 8), u32_at(records, 12));
    let (mut u, mut y) = ([0.0; 4], [0.0; 4]);
    let start = SYST::get_current();
    for t in 0..n {
        let row = (r * n + t) * (nu + ny);
        for j in 0..nu {
            u[j] = f64_at(records, row + j);
        }
        for j in 0..ny {
            y[j] = f64_at(records, row + nu + j);
        }
        stream.push(&u[..nu], &y[..ny])?;
    }
    Ok(since(start))
}

/// Record `r` pushed again and finished with `DRAWS` draws of seed 1 and
/// the record's number: the first eight numbers, the last draw and the
/// finish's ticks.
#[cfg(all(feature = "posterior", not(feature = "baseline")))]
fn draw(k: usize, r: usize, estimator: &Estimator<'_>, records: &[u8], work: &mut [f64]) {
    let q = estimator.n_parameters();
    let drawn = unsafe { &mut *core::ptr::addr_of_mut!(DRAWN) };
    let Some(draws) = drawn.get_mut(..DRAWS * q) else {
        hprintln!("draws {} {} error more than two parameters", k, r);
        return;
    };
    let mut theta = [0.0; 8];
    let result = Stream::new(estimator, work).and_then(|mut stream| {
        push_record(&mut stream, records, r)?;
        let start = SYST::get_current();
        stream.finish_with_draws(&mut theta[..q], &mut [], draws, 1, r as u64)?;
        Ok(since(start))
    });
    match result {
        Ok(ticks) => {
            let mut line = heapless_line();
            for v in draws.iter().take(8).chain(&draws[draws.len() - q..]) {
                line.push_hex(v.to_bits());
            }
            hprintln!("draws {} {} ok{} finish {}", k, r, line.as_str(), ticks);
        }
        Err(e) => hprintln!("draws {} {} error {}", k, r, e.code()),
    }
}

/// A window of a quarter of a record slid over all of the case's records,
/// finished at the end of each.
#[cfg(all(feature = "window", not(feature = "baseline")))]
fn slide(k: usize, estimator: &Estimator<'_>, records: &[u8], work: &mut [f64]) {
    let (count, n) = (u32_at(records, 0), u32_at(records, 4));
    let length = n / 4;
    hprintln!(
        "window {} length {} workspace {}",
        k,
        length,
        estimator.window_workspace_len(length)
    );
    if let Err(e) = Stream::window(estimator, length, work) {
        hprintln!("slide {} 0 error {}", k, e.code());
        return;
    }
    let q = estimator.n_parameters();
    let mut peak_stack = 0;
    for r in 0..count {
        let sp = paint();
        let mut theta = [0.0; 8];
        let result = Stream::resume(estimator, work).and_then(|mut stream| {
            let push = push_record(&mut stream, records, r)?;
            let start = SYST::get_current();
            let assessment = stream.finish(&mut theta[..q], &mut [])?;
            Ok((assessment, push, since(start)))
        });
        peak_stack = peak_stack.max(used(sp));
        match result {
            Ok((assessment, push, finish)) => {
                let mut line = heapless_line();
                for v in &theta[..q] {
                    line.push_hex(v.to_bits());
                }
                hprintln!(
                    "slide {} {} ok{} {} {} push {} finish {}",
                    k,
                    r,
                    line.as_str(),
                    u8::from(assessment.out_of_distribution()),
                    assessment.input_outside_family,
                    push,
                    finish
                );
            }
            Err(e) => hprintln!("slide {} {} error {}", k, r, e.code()),
        }
    }
    hprintln!("slide {} stack {}", k, peak_stack);
}

/// The same harness without the runtime: what the firmware costs without
/// it, so that the difference is the runtime's and the estimator's flash.
#[cfg(feature = "baseline")]
fn estimate_case(k: usize, blob: &[u8], records: &[u8], work: &mut [f64], peak_stack: &mut usize) {
    let (count, n, nu, ny) = (
        u32_at(records, 0),
        u32_at(records, 4),
        u32_at(records, 8),
        u32_at(records, 12),
    );
    // The blob is not touched, so that the linker drops it here.
    let _ = blob;
    hprintln!("case {} blob 0 workspace {}", k, work.len());
    for r in 0..count {
        let sp = paint();
        let mut sum = 0.0;
        for i in 0..n * (nu + ny) {
            sum += f64_at(records, r * n * (nu + ny) + i);
        }
        *peak_stack = (*peak_stack).max(used(sp));
        // The kinds of values the full harness prints (a string, a signed
        // error code, a flag byte, a mask), from the data so that they are not
        // folded away: formatting is the harness's flash, not the runtime's.
        let bits = sum.to_bits();
        let (code, flag) = ((bits & 7) as i32 - 4, (bits >> 3 & 1) as u8);
        let text = if flag == 1 { " odd" } else { " even" };
        hprintln!(
            "record {} {} sum {:x}{} {} {} {}",
            k,
            r,
            bits,
            text,
            code,
            flag,
            bits >> 60
        );
    }
}

/// A line of hex numbers in a fixed buffer (no allocator here).
#[cfg(not(feature = "baseline"))]
struct Line {
    bytes: [u8; 512],
    len: usize,
}

#[cfg(not(feature = "baseline"))]
fn heapless_line() -> Line {
    Line {
        bytes: [0; 512],
        len: 0,
    }
}

#[cfg(not(feature = "baseline"))]
impl Line {
    fn push_hex(&mut self, bits: u64) {
        const DIGITS: &[u8; 16] = b"0123456789abcdef";
        if self.len + 17 > self.bytes.len() {
            return;
        }
        self.bytes[self.len] = b' ';
        for i in 0..16 {
            self.bytes[self.len + 1 + i] = DIGITS[((bits >> (60 - 4 * i)) & 0xF) as usize];
        }
        self.len += 17;
    }
    fn as_str(&self) -> &str {
        core::str::from_utf8(&self.bytes[..self.len]).unwrap_or("")
    }
}
