//! Reusable scratch space for least-squares compression.

use faer::dyn_stack::{MemBuffer, MemStack, StackReq};
use faer::linalg::qr::no_pivoting::{factor, solve};
use faer::{Mat, Par};

use crate::fast::FastScratch;
use twostage_kernels::lagged::LaggedColumn;

/// One sample an estimate could not transform: it was replaced by the
/// smallest value of the transform's domain the training records showed.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FlooredSample {
    /// The output signal (0-based).
    pub output: usize,
    /// The sample (0-based).
    pub sample: usize,
    /// The value the record had there.
    pub value: f64,
}

/// The rank test of every least-squares solve, here and in the
/// microcontroller runtime (see the kernels).
pub use twostage_kernels::cholesky::RANK_TOLERANCE;

/// Scratch space for compressing records one after another without
/// allocating: it grows to the largest problem seen and then stays.
///
/// ```
/// use twostage_compress::{Arx, Compressor, Workspace};
/// use ndarray::Array2;
/// let arx = Arx::new(1, 1)?;
/// let u = Array2::from_shape_fn((50, 1), |(k, _)| ((k * k) % 7) as f64 - 3.0);
/// let mut y = Array2::zeros((50, 1));
/// for k in 1..50 { y[[k, 0]] = 0.5 * y[[k - 1, 0]] + 2.0 * u[[k - 1, 0]]; }
/// let mut work = Workspace::new();
/// let mut alpha = [0.0; 2];
/// arx.compress_into(u.view(), y.view(), &mut work, &mut alpha)?;
/// assert!((alpha[0] - 0.5).abs() < 1e-12 && (alpha[1] - 2.0).abs() < 1e-12);
/// # Ok::<(), twostage_compress::CompressError>(())
/// ```
pub struct Workspace {
    /// Regressor matrix, overwritten by its QR factors.
    pub(crate) phi: Mat<f64>,
    /// Right-hand side, overwritten by Q' y then the solution.
    pub(crate) rhs: Mat<f64>,
    /// Column norms of phi before factorization (for the rank check).
    pub(crate) norms: Vec<f64>,
    /// Scratch space of the estimate-time fast path.
    pub(crate) fast: FastScratch,
    /// Regressor columns of the fast path.
    pub(crate) columns: Vec<LaggedColumn>,
    /// Outputs after their transforms ([`crate::Transformed`]).
    pub(crate) transformed: Vec<f64>,
    /// A summary network's activations, layer in and layer out.
    pub(crate) learned: [Vec<f64>; 2],
    /// Samples the last estimate-path compression could not transform.
    pub(crate) floored: Vec<FlooredSample>,
    q_coeff: Mat<f64>,
    mem: MemBuffer,
    mem_req: StackReq,
}

impl std::fmt::Debug for Workspace {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Workspace")
            .field("rows", &self.phi.nrows())
            .field("cols", &self.phi.ncols())
            .field("scratch_bytes", &self.mem_req.size_bytes())
            .finish()
    }
}

impl Default for Workspace {
    fn default() -> Self {
        Self::new()
    }
}

impl Workspace {
    /// An empty workspace; it sizes itself on first use.
    pub fn new() -> Self {
        Self {
            phi: Mat::zeros(0, 0),
            rhs: Mat::zeros(0, 1),
            norms: Vec::new(),
            fast: FastScratch::default(),
            columns: Vec::new(),
            transformed: Vec::new(),
            learned: [Vec::new(), Vec::new()],
            floored: Vec::new(),
            q_coeff: Mat::zeros(1, 0),
            mem: MemBuffer::new(StackReq::EMPTY),
            mem_req: StackReq::EMPTY,
        }
    }

    /// The samples the last [`Compressor::compress_fast_into`] could not
    /// transform and took at their output's floor instead (empty unless
    /// the compressor transforms its outputs).
    ///
    /// [`Compressor::compress_fast_into`]: crate::Compressor::compress_fast_into
    pub fn floored_samples(&self) -> &[FlooredSample] {
        &self.floored
    }

    /// Make room for a `rows x cols` least-squares problem.
    pub(crate) fn prepare(&mut self, rows: usize, cols: usize) {
        if self.phi.nrows() != rows || self.phi.ncols() != cols {
            self.phi = Mat::zeros(rows, cols);
            self.rhs = Mat::zeros(rows, 1);
            let block = factor::recommended_block_size::<f64>(rows, cols);
            self.q_coeff = Mat::zeros(block, rows.min(cols));
            let req =
                factor::qr_in_place_scratch::<f64>(rows, cols, block, Par::Seq, Default::default())
                    .or(solve::solve_lstsq_in_place_scratch::<f64>(
                        rows,
                        cols,
                        block,
                        1,
                        Par::Seq,
                    ));
            if req.size_bytes() > self.mem_req.size_bytes() {
                self.mem = MemBuffer::new(req);
                self.mem_req = req;
            }
        }
        self.norms.clear();
        self.norms.resize(cols, 0.0);
    }

    /// Solve `min ||rhs - phi alpha||` by Householder QR, after `phi` and
    /// `rhs` were filled. Returns the index of the first column whose
    /// diagonal entry of R fails the rank check, or writes `alpha`.
    pub(crate) fn solve(&mut self, alpha: &mut [f64]) -> Option<usize> {
        let cols = self.phi.ncols();
        for (j, norm) in self.norms.iter_mut().enumerate() {
            *norm = self
                .phi
                .col_as_slice(j)
                .iter()
                .map(|v| v * v)
                .sum::<f64>()
                .sqrt();
        }
        let stack = MemStack::new(&mut self.mem);
        factor::qr_in_place(
            self.phi.as_mut(),
            self.q_coeff.as_mut(),
            Par::Seq,
            stack,
            Default::default(),
        );
        // faer's least squares never fails, even on rank-deficient input, so
        // the diagonal of R is checked here.
        for j in 0..cols {
            let r = self.phi[(j, j)].abs();
            let independent = r > RANK_TOLERANCE * self.norms[j] && self.norms[j] > 0.0;
            if !independent {
                return Some(j);
            }
        }
        let stack = MemStack::new(&mut self.mem);
        solve::solve_lstsq_in_place(
            self.phi.as_ref(),
            self.q_coeff.as_ref(),
            self.phi.as_ref(),
            self.rhs.as_mut(),
            Par::Seq,
            stack,
        );
        alpha.copy_from_slice(&self.rhs.col_as_slice(0)[..cols]);
        None
    }
}
