//! The modal model: every sensor a linear response to the air, the
//! power-on and the orientation's convection through a few first-order
//! lags.

use super::*;

/// Modes of the modal model: a linear network of this many nodes (ours:
/// a case, two blocks and one node nobody measures) has this many.
pub const MODES: usize = 4;
/// Bounds of a mode's time constant, s (ours).
pub(super) const MODE_TAU_S: (f64, f64) = (30.0, 36_000.0);
/// Convection inputs the modal model chooses from: the share of gravity
/// along each body axis (where a unit's convection acts is its own: the
/// twin's follows the sensor axis, another unit's the sensitive axis).
/// One is taken (all three at once over-fit the positions a held-out
/// stretch leaves unseen).
pub(super) const CONV_INPUTS: usize = 3;
/// Regressors per mode: the air through the mode's lag, the power-on step,
/// the convection input through the lag.
pub(super) const PER_MODE: usize = 3;
/// Unknowns per sensor: the regressors' weights and the offset.
pub(super) const MODAL_UNKNOWNS: usize = PER_MODE * MODES + 1;

/// The modes' time constants within bounds, and how far outside.
pub(super) fn clamp_modes(p: &[f64]) -> ([f64; MODES], f64) {
    let (lo, hi) = (MODE_TAU_S.0.ln(), MODE_TAU_S.1.ln());
    let mut out = [0.0; MODES];
    let mut outside = 0.0;
    for (o, v) in out.iter_mut().zip(p) {
        let c = v.clamp(lo, hi);
        outside += (v - c).powi(2);
        *o = c.exp();
    }
    (out, outside)
}

/// A block's regressors for modes `tau`: each is the block's mean of the
/// air through a first-order lag (soaked at the first air), of the step
/// 1 - exp(-t / tau) from power-on, and of the orientation's convection
/// input (gravity's share along body axis `axis`) through the lag. Exact
/// for the air held over each 10 s.
pub(super) fn modal_regressors(
    tau: &[f64; MODES],
    run: &[Block],
    axis: usize,
) -> Vec<[f64; PER_MODE * MODES]> {
    let Some(first) = run.first() else {
        return Vec::new();
    };
    let axis = axis.min(CONV_INPUTS - 1);
    let mut air = [first.air_c[0]; MODES];
    let mut grav = [first.gravity_abs[axis]; MODES];
    let mut t = 0.0;
    let decay = tau.map(|tm| (-STEP_S / tm).exp());
    run.iter()
        .map(|b| {
            let span = b.air_c.len() as f64 * STEP_S;
            let mut out = [0.0; PER_MODE * MODES];
            for m in 0..MODES {
                let tm = tau[m];
                // Through a gap on the block's first air and orientation.
                let g = b.gravity_abs[axis];
                if b.start_s > t {
                    let a = (-(b.start_s - t) / tm).exp();
                    air[m] = b.air_c[0] + (air[m] - b.air_c[0]) * a;
                    grav[m] = g + (grav[m] - g) * a;
                }
                let a = decay[m];
                let mean_frac = tm / STEP_S * (1.0 - a);
                let mut acc = 0.0;
                for &u in &b.air_c {
                    acc += u + (air[m] - u) * mean_frac;
                    air[m] = u + (air[m] - u) * a;
                }
                out[m] = acc / b.air_c.len() as f64;
                let (t0, t1) = (b.start_s, b.start_s + span);
                out[MODES + m] = 1.0 - tm / span * ((-t0 / tm).exp() - (-t1 / tm).exp());
                let ab = (-span / tm).exp();
                out[2 * MODES + m] = g + (grav[m] - g) * tm / span * (1.0 - ab);
                grav[m] = g + (grav[m] - g) * ab;
            }
            t = b.start_s + span;
            out
        })
        .collect()
}

/// Weight of the ridge on the regressors' weights and on the offsets, in
/// units of one block's squared residual (ours: keeps two near-equal modes
/// from trading huge opposite weights, and an offset the runs cannot tell
/// from the warm-up at zero).
pub(super) const MODAL_RIDGE: f64 = 1e-4;
pub(super) const MODAL_RIDGE_OFFSET: f64 = 1.0;

/// The modal model's cost on the blocks outside `held_out`.
#[derive(Clone, Copy)]
pub(super) struct ModalCost<'a> {
    pub(super) runs: &'a [Vec<Block>],
    pub(super) held_out: Option<usize>,
    /// The convection input's body axis (0 x, 1 y, 2 z).
    pub(super) axis: usize,
}

impl ModalCost<'_> {
    /// Per sensor, the weights solved on the training blocks, and the
    /// residuals of every block.
    pub(super) fn fit_at(&self, tau: &[f64; MODES]) -> Vec<Vec<[f64; 3]>> {
        type V = SVector<f64, MODAL_UNKNOWNS>;
        let regs: Vec<Vec<[f64; PER_MODE * MODES]>> = self
            .runs
            .iter()
            .map(|r| modal_regressors(tau, r, self.axis))
            .collect();
        let x_of = |r: &[f64; PER_MODE * MODES]| {
            let mut x = V::zeros();
            x.fixed_rows_mut::<{ PER_MODE * MODES }>(0)
                .copy_from_slice(r);
            x[MODAL_UNKNOWNS - 1] = 1.0;
            x
        };
        let mut ata = SMatrix::<f64, MODAL_UNKNOWNS, MODAL_UNKNOWNS>::zeros();
        let mut atb = [V::zeros(); 3];
        for (run, rr) in self.runs.iter().zip(&regs) {
            for (b, r) in run.iter().zip(rr) {
                if Some(b.fold) == self.held_out {
                    continue;
                }
                let x = x_of(r);
                ata += x * x.transpose();
                for (a, m) in atb.iter_mut().zip(b.measured) {
                    *a += x * m;
                }
            }
        }
        for k in 0..MODAL_UNKNOWNS - 1 {
            ata[(k, k)] += MODAL_RIDGE;
        }
        ata[(MODAL_UNKNOWNS - 1, MODAL_UNKNOWNS - 1)] += MODAL_RIDGE_OFFSET;
        let w: Vec<V> = match ata.cholesky() {
            Some(c) => atb.iter().map(|b| c.solve(b)).collect(),
            None => vec![V::zeros(); 3],
        };
        self.runs
            .iter()
            .zip(&regs)
            .map(|(run, rr)| {
                run.iter()
                    .zip(rr)
                    .map(|(b, r)| {
                        let x = x_of(r);
                        [0, 1, 2].map(|s| b.measured[s] - w[s].dot(&x))
                    })
                    .collect()
            })
            .collect()
    }
}

impl Squares for ModalCost<'_> {
    fn residuals(&self, p: &[f64]) -> Vec<f64> {
        let (tau, _) = clamp_modes(p);
        training_residuals(self.runs, &self.fit_at(&tau), self.held_out)
    }

    fn bounds(&self) -> (Vec<f64>, Vec<f64>) {
        let (lo, hi) = (MODE_TAU_S.0.ln(), MODE_TAU_S.1.ln());
        (vec![lo; MODES], vec![hi; MODES])
    }
}

impl CostFunction for ModalCost<'_> {
    type Param = Vec<f64>;
    type Output = f64;

    fn cost(&self, p: &Vec<f64>) -> Result<f64, Error> {
        let (tau, outside) = clamp_modes(p);
        let res = self.fit_at(&tau);
        let sse = training_sse(self.runs, &res, self.held_out) * (1.0 + outside);
        Ok(if sse.is_finite() { sse } else { f64::MAX })
    }
}

/// Sum of squares of the residuals in fold `k`.
pub(super) fn held_out_sse(runs: &[Vec<Block>], res: &[Vec<[f64; 3]>], k: usize) -> f64 {
    runs.iter()
        .zip(res)
        .flat_map(|(run, r)| run.iter().zip(r))
        .filter(|(b, _)| b.fold == k)
        .map(|(_, v)| v.iter().map(|x| x * x).sum::<f64>())
        .sum()
}

/// Sum of squares of the residuals outside `held_out`.
pub(super) fn training_sse(
    runs: &[Vec<Block>],
    res: &[Vec<[f64; 3]>],
    held_out: Option<usize>,
) -> f64 {
    let mut sse = 0.0;
    for (run, r) in runs.iter().zip(res) {
        for (b, v) in run.iter().zip(r) {
            if Some(b.fold) != held_out {
                sse += v.iter().map(|x| x * x).sum::<f64>();
            }
        }
    }
    sse
}

/// The modal model's modes on the blocks outside `held_out`, from a few
/// spreads of four time constants (ours: 30 s to 6 h between them).
pub(super) fn identify_modes(
    runs: &[Vec<Block>],
    held_out: Option<usize>,
    axis: usize,
) -> [f64; MODES] {
    let starts: Vec<Vec<f64>> = [
        [40.0f64, 200.0, 1000.0, 5000.0],
        [80.0, 400.0, 2000.0, 10_000.0],
        [150.0, 700.0, 3000.0, 20_000.0],
        [30.0, 120.0, 600.0, 3000.0],
        [300.0, 1000.0, 3000.0, 12_000.0],
    ]
    .iter()
    .map(|s| s.iter().map(|v| v.ln()).collect())
    .collect();
    let cost = ModalCost {
        runs,
        held_out,
        axis,
    };
    let p = multistart(cost, &starts, 2, 300);
    clamp_modes(&p).0
}
