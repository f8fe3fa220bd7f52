//! A program compiled to machine code by Cranelift: the
//! same instructions as the interpreter, in the same order, on the same
//! value table, so that both give the same bits. `+ - * /`, negation,
//! `abs` and `sqrt` are the processor's own (IEEE 754 rounds them exactly
//! as Rust does); every other function calls [`Unary::apply`] or
//! [`Binary::apply`], the one place each is defined.
//!
//! Where Cranelift cannot build for this processor, the program stays
//! interpreted: slower, the same values.

// Running machine code made at run time is unsafe by nature: the code
// reads and writes the value table through a raw pointer. What makes it
// sound: every slot an instruction names is checked against the table's
// length when the code is built, and `run` checks the table it is given
// is at least that long.
#![allow(unsafe_code)]

use std::collections::{BTreeSet, HashMap};
use std::mem::ManuallyDrop;

use cranelift_codegen::ir::condcodes::FloatCC;
use cranelift_codegen::ir::{AbiParam, InstBuilder, MemFlagsData, Value, types};
use cranelift_codegen::settings::{self, Configurable};
use cranelift_frontend::{FunctionBuilder, FunctionBuilderContext};
use cranelift_jit::{JITBuilder, JITModule};
use cranelift_module::{Linkage, Module};

use crate::instruction::Instruction;
use crate::ops::{Binary, Unary};

/// The machine code of one program, and the memory that holds it.
pub(crate) struct Native {
    module: ManuallyDrop<JITModule>,
    function: unsafe extern "C" fn(*mut f64, *const f64, *mut f64),
    /// The table's length the code needs: one past its highest slot.
    needs: usize,
    /// The lengths of the vectors read and given back.
    x_len: usize,
    out_len: usize,
}

// SAFETY: once built, the module is never used again but to free its
// memory on drop; the code is immutable and reads only the table it is
// given, so it may run from any thread, several at once.
unsafe impl Send for Native {}
// SAFETY: as for Send: `&Native` only gives `run`, which shares nothing.
unsafe impl Sync for Native {}

impl std::fmt::Debug for Native {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Native")
            .field("needs", &self.needs)
            .finish()
    }
}

impl Drop for Native {
    fn drop(&mut self) {
        // SAFETY: `function` points into this module's memory and dies
        // with `self`; nothing else holds the module.
        unsafe { ManuallyDrop::take(&mut self.module).free_memory() };
    }
}

impl Native {
    /// `code` compiled for this processor; `None` where Cranelift cannot
    /// build for it (the interpreter then runs the program).
    /// `from_x` are the slots read from the vector `x` beside the table,
    /// `to_out` those given back in `out` (see `Program`).
    pub(crate) fn compile(code: &[Instruction], from_x: &[u32], to_out: &[u32]) -> Option<Self> {
        let needs = code
            .iter()
            .flat_map(|i| {
                let ([a, b], to) = i.slots();
                [a, b, to]
            })
            .chain(from_x.iter().chain(to_out).copied())
            .map(|s| s as usize + 1)
            .max()
            .unwrap_or(0);
        let mut flags = settings::builder();
        // Cranelift's optimizer would move each value next to its first
        // use: a program of two records side by side then runs one
        // record's chain, then the other's, and the processor has nothing
        // to overlap. Our instructions are already reduced (common parts
        // once, per-record parts hoisted), and kept in their order the
        // records' chains interleave.
        flags.set("opt_level", "none").ok()?;
        let isa = cranelift_native::builder()
            .ok()?
            .finish(settings::Flags::new(flags))
            .ok()?;
        let mut builder = JITBuilder::with_isa(isa, cranelift_module::default_libcall_names());
        builder.symbol("twostage_unary", unary as *const u8);
        builder.symbol("twostage_binary", binary as *const u8);
        let mut module = JITModule::new(builder);
        let pointer = module.target_config().pointer_type();
        let mut signature = module.make_signature();
        for _ in 0..3 {
            signature.params.push(AbiParam::new(pointer));
        }
        let id = module
            .declare_function("program", Linkage::Local, &signature)
            .ok()?;
        let mut unary_signature = module.make_signature();
        unary_signature.params.push(AbiParam::new(types::I32));
        unary_signature.params.push(AbiParam::new(types::F64));
        unary_signature.returns.push(AbiParam::new(types::F64));
        let unary_id = module
            .declare_function("twostage_unary", Linkage::Import, &unary_signature)
            .ok()?;
        let mut binary_signature = unary_signature.clone();
        binary_signature.params.push(AbiParam::new(types::F64));
        let binary_id = module
            .declare_function("twostage_binary", Linkage::Import, &binary_signature)
            .ok()?;
        let mut context = module.make_context();
        context.func.signature = signature;
        let mut builder_context = FunctionBuilderContext::new();
        let mut b = FunctionBuilder::new(&mut context.func, &mut builder_context);
        let block = b.create_block();
        b.append_block_params_for_function_params(block);
        b.switch_to_block(block);
        b.seal_block(block);
        let (table, x_vector, out_vector) = match b.block_params(block) {
            &[table, x, out] => (table, x, out),
            _ => return None,
        };
        let unary_ref = module.declare_func_in_func(unary_id, b.func);
        let binary_ref = module.declare_func_in_func(binary_id, b.func);
        let memory = MemFlagsData::trusted();
        // Each slot's current value: loaded once, then kept in a
        // register; every slot written is stored at the end, so that the
        // table ends as the interpreter leaves it (but for the slots read
        // from the vector `x`, which the interpreter copies into it).
        let mut current: HashMap<u32, Value> = HashMap::new();
        let mut written: BTreeSet<u32> = BTreeSet::new();
        let offset = |slot: u32| i32::try_from(slot as usize * 8).ok();
        let read = |b: &mut FunctionBuilder<'_>,
                    current: &mut HashMap<u32, Value>,
                    slot: u32|
         -> Option<Value> {
            if let Some(&v) = current.get(&slot) {
                return Some(v);
            }
            let v = match from_x.iter().position(|&s| s == slot) {
                Some(i) => b
                    .ins()
                    .load(types::F64, memory, x_vector, offset(i as u32)?),
                None => b.ins().load(types::F64, memory, table, offset(slot)?),
            };
            current.insert(slot, v);
            Some(v)
        };
        for &instruction in code {
            let ([a, b_slot], to) = instruction.slots();
            let x = read(&mut b, &mut current, a)?;
            let y = read(&mut b, &mut current, b_slot)?;
            let value = match instruction {
                Instruction::Add(_) => b.ins().fadd(x, y),
                Instruction::Sub(_) => b.ins().fsub(x, y),
                Instruction::Mul(_) => b.ins().fmul(x, y),
                Instruction::Div(_) => b.ins().fdiv(x, y),
                Instruction::Copy(_) => x,
                Instruction::Unary(Unary::Neg, _) => b.ins().fneg(x),
                Instruction::Unary(Unary::Abs, _) => b.ins().fabs(x),
                Instruction::Unary(Unary::Sqrt, _) => b.ins().sqrt(x),
                Instruction::Unary(f, _) => {
                    let code = b.ins().iconst(types::I32, i64::from(f as u32));
                    let call = b.ins().call(unary_ref, &[code, x]);
                    b.inst_results(call)[0]
                }
                Instruction::Binary(Binary::Max, _) => {
                    // Binary::apply: b where a < b, else a.
                    let less = b.ins().fcmp(FloatCC::LessThan, x, y);
                    b.ins().select(less, y, x)
                }
                Instruction::Binary(Binary::Min, _) => {
                    // Binary::apply: b where b < a, else a.
                    let less = b.ins().fcmp(FloatCC::LessThan, y, x);
                    b.ins().select(less, y, x)
                }
                Instruction::Binary(f @ (Binary::Lt | Binary::Le | Binary::Gt | Binary::Ge), _) => {
                    // Ordered comparisons: false where either is NaN, as
                    // Rust's <, <=, > and >=.
                    let condition = match f {
                        Binary::Lt => FloatCC::LessThan,
                        Binary::Le => FloatCC::LessThanOrEqual,
                        Binary::Gt => FloatCC::GreaterThan,
                        _ => FloatCC::GreaterThanOrEqual,
                    };
                    let holds = b.ins().fcmp(condition, x, y);
                    let one = b.ins().f64const(1.0);
                    let zero = b.ins().f64const(0.0);
                    b.ins().select(holds, one, zero)
                }
                Instruction::Binary(f, _) => {
                    let code = b.ins().iconst(types::I32, i64::from(f as u32));
                    let call = b.ins().call(binary_ref, &[code, x, y]);
                    b.inst_results(call)[0]
                }
            };
            current.insert(to, value);
            written.insert(to);
        }
        for slot in written {
            b.ins().store(memory, current[&slot], table, offset(slot)?);
        }
        for (k, &slot) in to_out.iter().enumerate() {
            let v = read(&mut b, &mut current, slot)?;
            b.ins().store(memory, v, out_vector, offset(k as u32)?);
        }
        b.ins().return_(&[]);
        b.finalize(module.target_config());
        module.define_function(id, &mut context).ok()?;
        module.clear_context(&mut context);
        module.finalize_definitions().ok()?;
        let code = module.get_finalized_function(id);
        // SAFETY: the function was declared with this signature (one
        // pointer, no result) and the C calling convention.
        let function = unsafe {
            std::mem::transmute::<*const u8, unsafe extern "C" fn(*mut f64, *const f64, *mut f64)>(
                code,
            )
        };
        Some(Self {
            module: ManuallyDrop::new(module),
            function,
            needs,
            x_len: from_x.len(),
            out_len: to_out.len(),
        })
    }

    /// Runs the program on `values`, reading `x` and giving back `out`.
    ///
    /// # Panics
    /// If `values` is shorter than the program's slots, or `x` and `out`
    /// than its vectors: a table of another model, a programming error.
    #[inline]
    pub(crate) fn run(&self, values: &mut [f64], x: &[f64], out: &mut [f64]) {
        assert!(
            values.len() >= self.needs && x.len() >= self.x_len && out.len() >= self.out_len,
            "a table of {} slots and vectors of {} and {} for a program of {}, {} and {}",
            values.len(),
            x.len(),
            out.len(),
            self.needs,
            self.x_len,
            self.out_len
        );
        // SAFETY: every slot the code reads or writes is below `needs`,
        // within `values`; it reads `x_len` values of `x` and writes
        // `out_len` of `out`; the three do not overlap (one is shared,
        // two are exclusive borrows).
        unsafe { (self.function)(values.as_mut_ptr(), x.as_ptr(), out.as_mut_ptr()) }
    }
}

/// What the code calls for a function of one argument other than those
/// the processor does itself.
extern "C" fn unary(code: u32, x: f64) -> f64 {
    Unary::from_code(code).map_or(f64::NAN, |f| f.apply(x))
}

/// What the code calls for a function of two arguments other than the
/// four operators.
extern "C" fn binary(code: u32, a: f64, b: f64) -> f64 {
    Binary::from_code(code).map_or(f64::NAN, |f| f.apply(a, b))
}
