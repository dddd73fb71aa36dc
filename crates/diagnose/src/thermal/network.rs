//! The twin's network form as a fitted model: its searched shape and
//! bounds, the exact stepping of its nodes (a 60 s block as one linear
//! map), the linear quantities solved by least squares (variable
//! projection), and the cost the searches minimise.

use super::*;

/// The fitted quantities found by search, each within its bounds (ours:
/// wider than any gyro of this size; docs/diagnosis.md): time constants of
/// the mount node (1 s: none), the case, the two blocks and their
/// exchange, s, the convection gain, the blocks' capacity ratios, and the
/// heat sink's time constant, s, and capacity ratio (a baseplate can weigh
/// many times the case), and block 1's heat capacity over block 2's; then
/// the thermal effects' (`[thermal.effects]`, searched only in a form that
/// has them, [`Form`]): a sensor's own lag, s, a sensor's gain error, the
/// blocks' orientation coupling, a path from the air to a block, s, and
/// the case conductance's change with the air temperature, per degC.
pub(super) const SHAPE: [(&str, f64, f64); SHAPE_LEN] = [
    ("mount_tau_s", 1.0, 7200.0),
    ("case_tau_s", 60.0, 36_000.0),
    ("block1_tau_s", 30.0, 36_000.0),
    ("block2_tau_s", 30.0, 36_000.0),
    ("coupling_tau_s", 30.0, 1.0e6),
    ("convection_gain", 0.0, 5.0),
    ("block_capacity_ratio[0]", 0.0, 5.0),
    ("block_capacity_ratio[1]", 0.0, 5.0),
    ("sink_tau_s", 60.0, 36_000.0),
    ("sink_capacity_ratio", 0.0, 20.0),
    ("block_capacity_1_over_2", 0.05, 20.0),
    ("sensor_lag_s", 1.0, 3600.0),
    ("sensor_gain_error", -0.2, 0.2),
    ("orientation_coupling[0]", -0.9, 5.0),
    ("orientation_coupling[1]", -0.9, 5.0),
    ("air_path_tau_s", 60.0, 1.0e6),
    ("case_conductance_per_c", -0.03, 0.05),
];
pub(super) const SHAPE_LEN: usize = 17;
/// The network's own quantities, before the effects'.
pub(super) const BASE_LEN: usize = 11;
/// Where each quantity of [`SHAPE`] sits in a shape (the search works on
/// the vector; the code reads it by these names).
pub(super) mod at {
    pub const MOUNT_TAU: usize = 0;
    pub const CASE_TAU: usize = 1;
    pub const BLOCK1_TAU: usize = 2;
    pub const BLOCK2_TAU: usize = 3;
    pub const COUPLING_TAU: usize = 4;
    pub const CONVECTION: usize = 5;
    pub const RATIO1: usize = 6;
    pub const RATIO2: usize = 7;
    pub const SINK_TAU: usize = 8;
    pub const SINK_RATIO: usize = 9;
    pub const BLOCKS_1_OVER_2: usize = 10;
    pub const LAG_TAU: usize = 11;
    pub const SENSOR_GAIN: usize = 12;
    pub const COUPLING1: usize = 13;
    pub const COUPLING2: usize = 14;
    pub const AIR_PATH_TAU: usize = 15;
    pub const CONDUCTANCE: usize = 16;
}
/// The quantities searched in the simpler form: no heat sink (its
/// capacity ratio 0), blocks of equal capacity.
pub(super) const SIMPLE_LEN: usize = 8;
/// The searched quantities held as logarithms.
pub(super) const LOG_SCALED: [usize; 9] = [
    at::MOUNT_TAU,
    at::CASE_TAU,
    at::BLOCK1_TAU,
    at::BLOCK2_TAU,
    at::COUPLING_TAU,
    at::SINK_TAU,
    at::BLOCKS_1_OVER_2,
    at::LAG_TAU,
    at::AIR_PATH_TAU,
];

/// What a network holds besides its quantities: the full form's sink and
/// unequal blocks searched, and which thermal effects act (each with its
/// discrete choice: the sensor, the body axis, the block).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub(super) struct Form {
    /// The heat sink's two quantities and block 1's capacity over block
    /// 2's are searched (without, no sink and blocks of equal capacity).
    pub(super) full: bool,
    /// This sensor (0 T1, 1 T2, 2 TK) reads its node through a lag.
    pub(super) lag: Option<usize>,
    /// This sensor has a gain error.
    pub(super) gain: Option<usize>,
    /// The blocks' conductances to the case change with gravity along
    /// this body axis (0 x, 1 y, 2 z).
    pub(super) coupling: Option<usize>,
    /// A path from the air to this block (0 block 1, 1 block 2).
    pub(super) air_path: Option<usize>,
    /// The case's conductance changes with the air temperature.
    pub(super) conductance: bool,
}

impl Form {
    /// The shape's quantities a search moves in this form.
    pub(super) fn searched(&self) -> Vec<usize> {
        let mut out: Vec<usize> = (0..if self.full { BASE_LEN } else { SIMPLE_LEN }).collect();
        if self.lag.is_some() {
            out.push(at::LAG_TAU);
        }
        if self.gain.is_some() {
            out.push(at::SENSOR_GAIN);
        }
        if self.coupling.is_some() {
            out.extend([at::COUPLING1, at::COUPLING2]);
        }
        if self.air_path.is_some() {
            out.push(at::AIR_PATH_TAU);
        }
        if self.conductance {
            out.push(at::CONDUCTANCE);
        }
        out
    }

    /// Its nodes: the mount, the case, the two blocks, then the sink (when
    /// `sink`) and the lagging sensor's own node.
    pub(super) fn layout(&self, sink: bool) -> Layout {
        let mut n = 4;
        let sink = sink.then(|| {
            n += 1;
            n - 1
        });
        let mut sensors = BASE_SENSOR_NODES;
        if let Some(k) = self.lag {
            sensors[k] = n;
            n += 1;
        }
        Layout {
            nodes: n,
            sink,
            sensors,
        }
    }
}

/// Where a network's nodes sit in its state.
#[derive(Debug, Clone, Copy)]
pub(super) struct Layout {
    pub(super) nodes: usize,
    pub(super) sink: Option<usize>,
    /// The nodes T1, T2 and TK read.
    pub(super) sensors: [usize; 3],
}

/// Self-heating rises, degC: never negative (ours: at most 30).
pub(super) const RISE_MAX_C: f64 = 30.0;
/// The air gain's range (ours: a chamber sensor or a workspace gradient
/// off by up to a fifth).
pub(super) const AIR_GAIN: (f64, f64) = (0.8, 1.25);
/// Weight of the prior that the air gain is 1 and the offsets are 0, in
/// the units of one 60 s block's squared residual (ours: only breaks the
/// tie when the runs cannot tell them from the rises - a stretch without
/// the warm-up, a run at one temperature; an air gain off by 1 % costs as
/// much as a 0.5 degC offset would at a weight of 1, and the offsets' own
/// weight is far below the few warm-up blocks that tell them apart).
pub(super) const PRIOR_OFFSET: f64 = 1e-3;
pub(super) const PRIOR_GAIN: f64 = 2500.0;
/// Held-out gap above which the network form is said not to follow the
/// runs (ours: the tolerance; a network that fits leaves about a
/// hundredth on 60 s means).
pub const FORM_MISFIT_C: f64 = 0.05;

/// The searched quantities as the solver sees them: log time constants,
/// the convection gain and the capacity ratios.
pub(super) type Shape = [f64; SHAPE_LEN];

/// Within bounds, and how far outside they were (for a penalty).
pub(super) fn clamp_shape(q: &Shape) -> (Shape, f64) {
    let mut out = [0.0; SHAPE_LEN];
    let mut outside = 0.0;
    for (i, (&(_, lo, hi), v)) in SHAPE.iter().zip(q).enumerate() {
        let (lo, hi) = if LOG_SCALED.contains(&i) {
            (lo.ln(), hi.ln())
        } else {
            (lo, hi)
        };
        let c = v.clamp(lo, hi);
        outside += (v - c).powi(2);
        out[i] = c;
    }
    (out, outside)
}

pub(super) fn shape_of(c: &ThermalConfig) -> Shape {
    let fx = &c.effects;
    let form = form_of(c);
    let off = off();
    let (m, _) = clamp_shape(&[
        c.mount_tau_s.max(1.0).ln(),
        c.case_tau_s.ln(),
        c.block1_tau_s.ln(),
        c.block2_tau_s.ln(),
        c.coupling_tau_s.ln(),
        c.convection_gain,
        c.block_capacity_ratio[0],
        c.block_capacity_ratio[1],
        if c.sink_tau_s > 0.0 {
            c.sink_tau_s.ln()
        } else {
            SINK_START_S.ln()
        },
        if c.sink_tau_s > 0.0 {
            c.sink_capacity_ratio
        } else {
            0.0
        },
        c.block_capacity_1_over_2.ln(),
        form.lag
            .map_or(off[at::LAG_TAU], |k| fx.sensor_lag_s[k].ln()),
        form.gain.map_or(0.0, |k| fx.sensor_gain_error[k]),
        fx.orientation_coupling[0],
        fx.orientation_coupling[1],
        form.air_path
            .map_or(off[at::AIR_PATH_TAU], |k| fx.air_path_tau_s[k].ln()),
        fx.case_conductance_per_c,
    ]);
    m
}

/// The form of a twin's network: its full form's quantities, and its
/// effects as the fitted network holds them (one lagging sensor, one
/// gain error, one block with an air path: the largest of each; the
/// orientation coupling on the body axis its axis lies most along).
pub(super) fn form_of(c: &ThermalConfig) -> Form {
    let fx = &c.effects;
    let largest = |v: &[f64]| {
        (0..v.len())
            .filter(|&k| v[k] != 0.0)
            .max_by(|&a, &b| v[a].abs().total_cmp(&v[b].abs()))
    };
    let axis = fx.orientation_axis();
    Form {
        full: c.sink_tau_s > 0.0 && c.sink_capacity_ratio > 0.0 || c.block_capacity_1_over_2 != 1.0,
        lag: largest(&fx.sensor_lag_s),
        gain: largest(&fx.sensor_gain_error),
        coupling: (fx.orientation_coupling != [0.0; 2])
            .then(|| largest(&[axis.x, axis.y, axis.z]))
            .flatten(),
        air_path: largest(
            &fx.air_path_tau_s
                .map(|t| if t > 0.0 { 1.0 / t } else { 0.0 }),
        ),
        conductance: fx.case_conductance_per_c != 0.0,
    }
}

/// A shape's values where nothing is searched: no sink (its time
/// constant where a search that adds one starts), blocks of equal
/// capacity, and the effects' where a search of them starts (a lag of a
/// minute, an air path of 10,000 s; ours).
pub(super) fn off() -> Shape {
    let mut q = [0.0; SHAPE_LEN];
    q[at::SINK_TAU] = SINK_START_S.ln();
    q[at::LAG_TAU] = 60.0f64.ln();
    q[at::AIR_PATH_TAU] = 10_000.0f64.ln();
    q
}

/// A network with a heat sink on the case.
pub(super) fn has_sink(q: &Shape) -> bool {
    q[at::SINK_RATIO] > 0.0
}

/// The sink's time constant a shape without one carries, s (where a
/// search that adds one starts).
pub(super) const SINK_START_S: f64 = 1500.0;

/// Inputs of the fitted network: air, case rise, block 1 rise, block 2
/// rise.
pub(super) const INPUTS: usize = 4;
/// Per node (mount, case, block 1, block 2, and the sink when there is
/// one), its response to each input.
pub(super) type Nodes<const N: usize> = SMatrix<f64, N, INPUTS>;

/// What a block's orientation and air change in the network: the
/// blocks' exchange (convection), the orientation coupling's share of
/// gravity, and the air temperature the case's conductance follows (20
/// degC without the effect). Blocks with the same key share one
/// discretisation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Key {
    pub(super) convection: f64,
    pub(super) coupling: f64,
    pub(super) air_c: f64,
}

/// The air grid the case conductance's discretisations are taken on,
/// degC; a block's is interpolated linearly between the two around its
/// mean air (ours: the maps are smooth in the air temperature, their
/// second derivative over a grid step a few 1e-8 of themselves, so the
/// interpolation is closer to the exact map than a rounding to a
/// 0.5 degC grid was, with a tenth of the matrix exponentials).
const AIR_GRID_C: f64 = 5.0;

impl Key {
    /// The block's key at the grid air below its mean air and, with the
    /// conductance effect, the weight of the grid air above (0 without).
    fn of(q: &Shape, form: &Form, b: &Block) -> (Self, f64) {
        let (air_c, above) = if form.conductance {
            let mean = b.air_c.iter().sum::<f64>() / BLOCK_STEPS as f64;
            let below = (mean / AIR_GRID_C).floor() * AIR_GRID_C;
            (below, (mean - below) / AIR_GRID_C)
        } else {
            (twin_effects::CONDUCTANCE_REFERENCE_C, 0.0)
        };
        let key = Self {
            convection: 1.0 + q[at::CONVECTION] * b.gravity_along_axis,
            coupling: form.coupling.map_or(0.0, |a| b.gravity_abs[a]),
            air_c,
        };
        (key, above)
    }

    /// The key at the grid air above.
    fn above(self) -> Self {
        Self {
            air_c: self.air_c + AIR_GRID_C,
            ..self
        }
    }
}

/// The state transition over `dt_s` of the network's `N` nodes (mount,
/// case, block 1, block 2, then the sink and a lagging sensor's node when
/// the layout has them) and its input matrix for the [`INPUTS`], exact for
/// inputs held over the step (`M` = `N` + [`INPUTS`]: the augmented matrix
/// whose exponential holds both). The twin's equations
/// (`twin::thermal::ThermalNetwork::step_in`), the rises heat inputs.
pub(super) fn discretize<const N: usize, const M: usize>(
    q: &Shape,
    form: &Form,
    layout: &Layout,
    key: &Key,
    dt_s: f64,
) -> (SMatrix<f64, N, N>, Nodes<N>)
where
    Const<N>: DimMin<Const<N>, Output = Const<N>>,
    Const<M>: DimMin<Const<M>, Output = Const<M>>,
{
    let m = rates::<N, M>(q, form, layout, key);
    // The augmented matrix's exponential is [[e^(A dt), G], [0, I]] with
    // G = (A dt)^-1 (e^(A dt) - I) B dt: the exponential of the nodes'
    // matrix alone and one solve, a fifth of the work of the augmented
    // one's. The subtraction loses the digits by which the slowest mode
    // is slower than the step: at the search box's slowest corner (a mode
    // of 1e6 s against 10 s) G is 4e-13 of itself off the augmented
    // exponential's (a test), against the forward differences' step of
    // 1.5e-8. A is never singular (every node reaches the air); should a
    // pivot be exactly zero or the solve not finite, the augmented
    // exponential is taken.
    let a = m.fixed_view::<N, N>(0, 0).into_owned() * dt_s;
    let b = m.fixed_view::<N, INPUTS>(0, N).into_owned() * dt_s;
    let phi = a.exp();
    let gamma = a
        .lu()
        .solve(&((phi - SMatrix::<f64, N, N>::identity()) * b))
        .filter(|g| g.iter().all(|v| v.is_finite()));
    match gamma {
        Some(gamma) => (phi, gamma),
        None => {
            let e = (m * dt_s).exp();
            (
                e.fixed_view::<N, N>(0, 0).into_owned(),
                e.fixed_view::<N, INPUTS>(0, N).into_owned(),
            )
        }
    }
}

/// The network's rates as the augmented matrix `[[A, B], [0, 0]]`: the
/// nodes' matrix `A` (N x N) and the inputs' `B` (N x [`INPUTS`]).
pub(super) fn rates<const N: usize, const M: usize>(
    q: &Shape,
    form: &Form,
    layout: &Layout,
    key: &Key,
) -> SMatrix<f64, M, M> {
    debug_assert!(M == N + INPUTS && N == layout.nodes);
    let [tm, tk, t1, t2, tc, ts] = [
        at::MOUNT_TAU,
        at::CASE_TAU,
        at::BLOCK1_TAU,
        at::BLOCK2_TAU,
        at::COUPLING_TAU,
        at::SINK_TAU,
    ]
    .map(|i| q[i].exp());
    let kc = key.convection / tc;
    // One conductance between the blocks, seen from both ends.
    let kc2 = kc * q[at::BLOCKS_1_OVER_2].exp();
    // The orientation scales each block's conductance to the case (seen
    // from the block and, through its capacity ratio, from the case).
    let floor = twin_effects::CONDUCTANCE_FLOOR;
    let (f1, f2) = match form.coupling {
        Some(_) => (
            (1.0 + q[at::COUPLING1] * key.coupling).max(floor),
            (1.0 + q[at::COUPLING2] * key.coupling).max(floor),
        ),
        None => (1.0, 1.0),
    };
    let sc = if form.conductance {
        let c = q[at::CONDUCTANCE] * (key.air_c - twin_effects::CONDUCTANCE_REFERENCE_C);
        (1.0 + c).max(floor)
    } else {
        1.0
    };
    let (r1, r2) = (f1 * q[at::RATIO1] / t1, f2 * q[at::RATIO2] / t2);
    let mut m = SMatrix::<f64, M, M>::zeros();
    m[(0, 0)] = -1.0 / tm;
    m[(1, 0)] = sc / tk;
    m[(1, 1)] = -sc / tk - r1 - r2;
    m[(1, 2)] = r1;
    m[(1, 3)] = r2;
    if let Some(k) = layout.sink {
        let rs = q[at::SINK_RATIO] / ts;
        m[(1, 1)] -= rs;
        m[(1, k)] = rs;
        m[(k, 1)] = 1.0 / ts;
        m[(k, k)] = -1.0 / ts;
    }
    m[(2, 1)] = f1 / t1;
    m[(2, 2)] = -f1 / t1 - kc;
    m[(2, 3)] = kc;
    m[(3, 1)] = f2 / t2;
    m[(3, 3)] = -f2 / t2 - kc2;
    m[(3, 2)] = kc2;
    m[(0, N)] = 1.0 / tm;
    m[(1, N + 1)] = 1.0 / tk;
    m[(2, N + 2)] = 1.0 / t1;
    m[(3, N + 3)] = 1.0 / t2;
    if let Some(b) = form.air_path {
        let kp = 1.0 / q[at::AIR_PATH_TAU].exp();
        m[(2 + b, 2 + b)] -= kp;
        m[(2 + b, N)] += kp;
    }
    if let Some(s) = form.lag {
        let (node, from) = (layout.sensors[s], BASE_SENSOR_NODES[s]);
        let kl = 1.0 / q[at::LAG_TAU].exp();
        m[(node, from)] = kl;
        m[(node, node)] = -kl;
    }
    m
}

/// Per block and sensor (T1, T2, TK), the mean response to each input
/// (air, case rise, block 1 rise, block 2 rise): the network soaked at the
/// first air, powered from t = 0, driven by the blocks' air. The readings
/// are linear in these: `gain * air + rises + offset`.
pub(super) type Responses = Vec<[[f64; 4]; 3]>;

pub(super) fn simulate(q: &Shape, form: &Form, run: &[Block]) -> Responses {
    // Without a sink or a lagging sensor, their nodes are left out.
    let layout = form.layout(has_sink(q));
    let mut resp = match layout.nodes {
        4 => simulate_nodes::<4, 8>(q, form, &layout, run),
        5 => simulate_nodes::<5, 9>(q, form, &layout, run),
        _ => simulate_nodes::<6, 10>(q, form, &layout, run),
    };
    if let Some(s) = form.gain {
        let g = 1.0 + q[at::SENSOR_GAIN];
        for rb in &mut resp {
            for v in &mut rb[s] {
                *v *= g;
            }
        }
    }
    resp
}

fn simulate_nodes<const N: usize, const M: usize>(
    q: &Shape,
    form: &Form,
    layout: &Layout,
    run: &[Block],
) -> Responses
where
    Const<N>: DimMin<Const<N>, Output = Const<N>>,
    Const<M>: DimMin<Const<M>, Output = Const<M>>,
{
    let Some(first) = run.first() else {
        return Vec::new();
    };
    let mut cache = Vec::new();
    let mut x = Nodes::<N>::zeros();
    for i in 0..N {
        x[(i, 0)] = first.air_c[0];
    }
    let advance = |x: &mut Nodes<N>, phi: &SMatrix<f64, N, N>, gamma: &Nodes<N>, air: f64| {
        let mut u = *gamma;
        u.column_mut(0).scale_mut(air);
        *x = phi * *x + u;
    };
    type Cached<const N: usize> = (Key, SMatrix<f64, N, N>, Nodes<N>, BlockStep<N>);
    // Consecutive blocks mostly share their keys: the last two found are
    // looked at first (with the conductance effect the cache holds a key
    // per grid air and orientation, and its search from the start was a
    // twentieth of the evaluation).
    let mut last = [0usize; 2];
    let mut at_key = |cache: &mut Vec<Cached<N>>, key: Key| {
        let k = match last
            .into_iter()
            .find(|&k| cache.get(k).is_some_and(|c| c.0 == key))
            .or_else(|| cache.iter().position(|c| c.0 == key))
        {
            Some(k) => k,
            None => {
                let (p, g) = discretize::<N, M>(q, form, layout, &key, STEP_S);
                cache.push((key, p, g, BlockStep::new(&p, &g, &layout.sensors)));
                cache.len() - 1
            }
        };
        last = [k, last[0]];
        k
    };
    let mut t = 0.0;
    let mut blended = None;
    run.iter()
        .map(|b| {
            let (key, above) = Key::of(q, form, b);
            let k = at_key(&mut cache, key);
            let k_above = (above > 0.0).then(|| at_key(&mut cache, key.above()));
            let whole = match k_above {
                None => &cache[k].3,
                Some(j) => &*blended.insert(BlockStep::blend(&cache[k].3, &cache[j].3, above)),
            };
            // Up to the block (gaps between records) on its first air,
            // by the one-step maps (blended as the block's).
            if t < b.start_s - 1e-9 {
                let (phi, gamma) = match k_above {
                    None => (cache[k].1, cache[k].2),
                    Some(j) => {
                        let (lo, hi) = (&cache[k], &cache[j]);
                        let w = |a: f64, b: f64| a + above * (b - a);
                        (lo.1.zip_map(&hi.1, w), lo.2.zip_map(&hi.2, w))
                    }
                };
                while t < b.start_s - 1e-9 {
                    let dt = (b.start_s - t).min(STEP_S);
                    if dt == STEP_S {
                        advance(&mut x, &phi, &gamma, b.air_c[0]);
                    } else {
                        let (p, g) = discretize::<N, M>(q, form, layout, &key, dt);
                        advance(&mut x, &p, &g, b.air_c[0]);
                    }
                    t += dt;
                }
            }
            t += STEP_S * BLOCK_STEPS as f64;
            whole.apply(&mut x, &b.air_c)
        })
        .collect()
}

/// Nodes of T1, T2 and TK without a lagging sensor: block 1, block 2,
/// the case.
pub(super) const BASE_SENSOR_NODES: [usize; 3] = [2, 3, 1];
/// Steps of [`STEP_S`] in a block.
pub(super) const BLOCK_STEPS: usize = AVERAGING_S / STEP_S as usize;
const _: () = assert!(BLOCK_STEPS * STEP_S as usize == AVERAGING_S);

/// A whole block of [`BLOCK_STEPS`] steps as one linear map: the state at
/// its end and the sensor nodes' mean over it (the steps' trapezoids)
/// from the state at its start, the air of each step and the rises. The
/// same arithmetic as stepping through the block, a quarter of the work.
pub(super) struct BlockStep<const N: usize> {
    pub(super) end: SMatrix<f64, N, N>,
    pub(super) mean: SMatrix<f64, 3, N>,
    /// Per step, its air's weight on the end state and on the mean.
    pub(super) air_end: [SVector<f64, N>; BLOCK_STEPS],
    pub(super) air_mean: [SVector<f64, 3>; BLOCK_STEPS],
    /// The rises' (held over the block) on the end state and the mean.
    pub(super) rise_end: SMatrix<f64, N, 3>,
    pub(super) rise_mean: SMatrix<f64, 3, 3>,
}

impl<const N: usize> BlockStep<N> {
    pub(super) fn new(phi: &SMatrix<f64, N, N>, gamma: &Nodes<N>, sensors: &[usize; 3]) -> Self {
        const K: usize = BLOCK_STEPS;
        // pow[k] = phi^k.
        let mut pow = vec![SMatrix::<f64, N, N>::identity()];
        for k in 1..=K {
            pow.push(phi * pow[k - 1]);
        }
        // The trapezoids' weights on the states 0..=K, over the block.
        let w = |k: usize| if k == 0 || k == K { 0.5 } else { 1.0 } / K as f64;
        let rows =
            |m: &SMatrix<f64, N, N>| SMatrix::<f64, 3, N>::from_fn(|r, c| m[(sensors[r], c)]);
        let mean_full = (0..=K).fold(SMatrix::<f64, N, N>::zeros(), |a, k| a + pow[k] * w(k));
        // An input at step j reaches state k > j through phi^(k - 1 - j).
        let after = |j: usize| {
            let end = pow[K - 1 - j];
            let mean = ((j + 1)..=K).fold(SMatrix::<f64, N, N>::zeros(), |a, k| {
                a + pow[k - 1 - j] * w(k)
            });
            (end, mean)
        };
        let g_air: SVector<f64, N> = gamma.column(0).into_owned();
        let g_rise: SMatrix<f64, N, 3> = gamma.fixed_columns::<3>(1).into_owned();
        let mut air_end = [SVector::<f64, N>::zeros(); K];
        let mut air_mean = [SVector::<f64, 3>::zeros(); K];
        let (mut sum_end, mut sum_mean) = (SMatrix::<f64, N, N>::zeros(), SMatrix::zeros());
        for j in 0..K {
            let (end, mean) = after(j);
            air_end[j] = end * g_air;
            air_mean[j] = rows(&mean) * g_air;
            sum_end += end;
            sum_mean += mean;
        }
        Self {
            end: pow[K],
            mean: rows(&mean_full),
            air_end,
            air_mean,
            rise_end: sum_end * g_rise,
            rise_mean: rows(&sum_mean) * g_rise,
        }
    }

    /// The map `a + w (b - a)`: between the maps at two air temperatures.
    fn blend(a: &Self, b: &Self, w: f64) -> Self {
        let lerp = |x: f64, y: f64| x + w * (y - x);
        Self {
            end: a.end.zip_map(&b.end, lerp),
            mean: a.mean.zip_map(&b.mean, lerp),
            air_end: std::array::from_fn(|j| a.air_end[j].zip_map(&b.air_end[j], lerp)),
            air_mean: std::array::from_fn(|j| a.air_mean[j].zip_map(&b.air_mean[j], lerp)),
            rise_end: a.rise_end.zip_map(&b.rise_end, lerp),
            rise_mean: a.rise_mean.zip_map(&b.rise_mean, lerp),
        }
    }

    /// Step `x` over the block with the air of each step; the sensors'
    /// mean responses.
    pub(super) fn apply(&self, x: &mut Nodes<N>, air: &[f64; BLOCK_STEPS]) -> [[f64; 4]; 3] {
        let mut mean = self.mean * *x;
        let mut end = self.end * *x;
        for (j, &a) in air.iter().enumerate() {
            let mut c = end.column_mut(0);
            c.axpy(a, &self.air_end[j], 1.0);
            let mut m = mean.column_mut(0);
            m.axpy(a, &self.air_mean[j], 1.0);
        }
        for r in 0..3 {
            let mut c = end.column_mut(r + 1);
            c += self.rise_end.column(r);
            let mut m = mean.column_mut(r + 1);
            m += self.rise_mean.column(r);
        }
        *x = end;
        let mut out = [[0.0; 4]; 3];
        for (s, o) in out.iter_mut().enumerate() {
            for (j, v) in o.iter_mut().enumerate() {
                *v = mean[(s, j)];
            }
        }
        out
    }
}

/// The linear quantities given the responses: air gain, the three rises,
/// the three sensor offsets. A sensor's reading in a block is its row
/// (its four responses, then a one for its own offset and zeros for the
/// others') times them.
pub(super) type Linear = [f64; 7];

/// Least squares for the linear quantities on the blocks outside
/// `held_out`, with the weak prior, the rises kept within 0..RISE_MAX_C
/// and the gain within AIR_GAIN (a quantity past its bound is held there
/// and the rest solved again).
pub(super) fn solve_linear(
    runs: &[Vec<Block>],
    resp: &[Responses],
    held_out: Option<usize>,
) -> Linear {
    // The normal equations of the rows ([`Linear`]), summed by their structure:
    // the responses' products, each response's sum against its sensor's
    // offset, and each sensor's count (the upper triangle, mirrored).
    // (Summed in plain arrays, the same sums in the same order: indexing
    // the matrices here was a tenth of an evaluation.)
    let mut sums = [[0.0f64; 7]; 7];
    let mut rhs = [0.0f64; 7];
    for (run, r) in runs.iter().zip(resp) {
        for (b, rb) in run.iter().zip(r) {
            if Some(b.fold) == held_out {
                continue;
            }
            for (s, x) in rb.iter().enumerate() {
                let m = b.measured[s];
                for i in 0..4 {
                    for j in i..4 {
                        sums[i][j] += x[i] * x[j];
                    }
                    sums[i][4 + s] += x[i];
                    rhs[i] += x[i] * m;
                }
                sums[4 + s][4 + s] += 1.0;
                rhs[4 + s] += m;
            }
        }
    }
    let mut ata = SMatrix::<f64, 7, 7>::from_fn(|i, j| sums[i][j]);
    let mut atb = SVector::<f64, 7>::from_fn(|i, _| rhs[i]);
    ata.fill_lower_triangle_with_upper_triangle();
    ata[(0, 0)] += PRIOR_GAIN;
    atb[0] += PRIOR_GAIN;
    for k in 4..7 {
        ata[(k, k)] += PRIOR_OFFSET;
    }
    let mut fixed: [Option<f64>; 7] = [None; 7];
    let mut theta = [1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0];
    for _ in 0..8 {
        let free: Vec<usize> = (0..7).filter(|&i| fixed[i].is_none()).collect();
        let n = free.len();
        let mut a = nalgebra::DMatrix::<f64>::zeros(n, n);
        let mut b = nalgebra::DVector::<f64>::zeros(n);
        for (i, &fi) in free.iter().enumerate() {
            b[i] = atb[fi];
            for (k, v) in fixed.iter().enumerate() {
                if let Some(v) = v {
                    b[i] -= ata[(fi, k)] * v;
                }
            }
            for (j, &fj) in free.iter().enumerate() {
                a[(i, j)] = ata[(fi, fj)];
            }
        }
        let Some(sol) = a.cholesky().map(|c| c.solve(&b)) else {
            break;
        };
        for (i, &fi) in free.iter().enumerate() {
            theta[fi] = sol[i];
        }
        for (k, v) in fixed.iter().enumerate() {
            if let Some(v) = v {
                theta[k] = *v;
            }
        }
        let mut moved = false;
        for &k in &free {
            let (lo, hi) = if k == 0 {
                AIR_GAIN
            } else if k < 4 {
                (0.0, RISE_MAX_C)
            } else {
                continue;
            };
            if !(lo..=hi).contains(&theta[k]) {
                fixed[k] = Some(theta[k].clamp(lo, hi));
                moved = true;
            }
        }
        if !moved {
            break;
        }
    }
    theta
}

/// The readings the linear quantities `lin` predict from a block's
/// responses: a sensor's row ([`Linear`]) times them, its other
/// sensors' offsets left out (their terms are zeros).
pub(super) fn predict(rb: &[[f64; 4]; 3], lin: &Linear) -> [f64; 3] {
    [0, 1, 2].map(|s| {
        let x = &rb[s];
        x[0] * lin[0] + x[1] * lin[1] + x[2] * lin[2] + x[3] * lin[3] + lin[4 + s]
    })
}

/// Sum of squares of the block residuals outside `held_out`, the linear
/// quantities solved for each searched shape (variable projection).
#[derive(Clone, Copy)]
pub(super) struct Cost<'a> {
    pub(super) runs: &'a [Vec<Block>],
    pub(super) held_out: Option<usize>,
    /// The form searched: which quantities move and which effects act.
    pub(super) form: Form,
}

impl Cost<'_> {
    /// The quantities the search moves, from a shape.
    pub(super) fn searched(&self, q: &Shape) -> Vec<f64> {
        self.form.searched().iter().map(|&i| q[i]).collect()
    }

    /// The shape of the searched quantities `p` (the rest as [`off`]),
    /// within bounds, and how far outside they were.
    pub(super) fn shape(&self, p: &[f64]) -> (Shape, f64) {
        let mut q = off();
        for (&i, v) in self.form.searched().iter().zip(p) {
            q[i] = *v;
        }
        clamp_shape(&q)
    }

    /// The linear quantities and the residuals (measured - simulated) per
    /// block at `q`.
    pub(super) fn fit_at(&self, q: &Shape) -> (Linear, Vec<Vec<[f64; 3]>>) {
        let resp: Vec<Responses> = self
            .runs
            .iter()
            .map(|r| simulate(q, &self.form, r))
            .collect();
        let lin = solve_linear(self.runs, &resp, self.held_out);
        let res = self
            .runs
            .iter()
            .zip(&resp)
            .map(|(run, r)| {
                run.iter()
                    .zip(r)
                    .map(|(b, rb)| {
                        let p = predict(rb, &lin);
                        [0, 1, 2].map(|k| b.measured[k] - p[k])
                    })
                    .collect()
            })
            .collect();
        (lin, res)
    }
}

/// The residuals of the blocks outside `held_out`, flattened.
pub(super) fn training_residuals(
    runs: &[Vec<Block>],
    res: &[Vec<[f64; 3]>],
    held_out: Option<usize>,
) -> Vec<f64> {
    runs.iter()
        .zip(res)
        .flat_map(|(run, r)| run.iter().zip(r))
        .filter(|(b, _)| Some(b.fold) != held_out)
        .flat_map(|(_, v)| *v)
        .collect()
}

impl Squares for Cost<'_> {
    fn residuals(&self, p: &[f64]) -> Vec<f64> {
        let (q, _) = self.shape(p);
        training_residuals(self.runs, &self.fit_at(&q).1, self.held_out)
    }

    fn bounds(&self) -> (Vec<f64>, Vec<f64>) {
        self.form
            .searched()
            .iter()
            .map(|&i| {
                let (_, lo, hi) = SHAPE[i];
                if LOG_SCALED.contains(&i) {
                    (lo.ln(), hi.ln())
                } else {
                    (lo, hi)
                }
            })
            .unzip()
    }
}

impl CostFunction for Cost<'_> {
    type Param = Vec<f64>;
    type Output = f64;

    fn cost(&self, p: &Vec<f64>) -> Result<f64, Error> {
        let (q, outside) = self.shape(p);
        // fit_at's residuals summed as they come (the search's hot path).
        let resp: Vec<Responses> = self
            .runs
            .iter()
            .map(|r| simulate(&q, &self.form, r))
            .collect();
        let lin = solve_linear(self.runs, &resp, self.held_out);
        let mut sse = 0.0;
        for (run, r) in self.runs.iter().zip(&resp) {
            for (b, rb) in run.iter().zip(r) {
                if Some(b.fold) != self.held_out {
                    let p = predict(rb, &lin);
                    sse += (0..3).map(|k| (b.measured[k] - p[k]).powi(2)).sum::<f64>();
                }
            }
        }
        // Outside the bounds the cost grows, so the simplex turns back.
        let sse = sse * (1.0 + outside);
        Ok(if sse.is_finite() { sse } else { f64::MAX })
    }
}
/// The fitted network as the twin's configuration (its effects as
/// `[thermal.effects]`, the rest of them off).
pub(super) fn to_config(
    base: &ThermalConfig,
    q: &Shape,
    form: &Form,
    lin: &Linear,
) -> ThermalConfig {
    let mut c = base.clone();
    // (exp(ln(x)) can land a rounding below the bound.)
    let tau = |i: usize| q[i].exp().clamp(SHAPE[i].1, SHAPE[i].2);
    c.mount_tau_s = if q[at::MOUNT_TAU] <= SHAPE[at::MOUNT_TAU].1.ln() + 1e-9 {
        0.0
    } else {
        tau(at::MOUNT_TAU)
    };
    c.case_tau_s = tau(at::CASE_TAU);
    c.block1_tau_s = tau(at::BLOCK1_TAU);
    c.block2_tau_s = tau(at::BLOCK2_TAU);
    c.coupling_tau_s = tau(at::COUPLING_TAU);
    c.convection_gain = q[at::CONVECTION];
    c.block_capacity_ratio = [q[at::RATIO1], q[at::RATIO2]];
    (c.sink_tau_s, c.sink_capacity_ratio) = if has_sink(q) {
        (tau(at::SINK_TAU), q[at::SINK_RATIO])
    } else {
        (0.0, 0.0)
    };
    c.block_capacity_1_over_2 = tau(at::BLOCKS_1_OVER_2);
    c.air_gain = lin[0];
    c.case_rise_c = lin[1];
    c.block1_rise_c = lin[2];
    c.block2_rise_c = lin[3];
    c.sensor_offset_c = [lin[4], lin[5], lin[6]];
    let mut fx = crate::twin::config::ThermalEffects::default();
    if let Some(k) = form.lag {
        fx.sensor_lag_s[k] = tau(at::LAG_TAU);
    }
    if let Some(k) = form.gain {
        fx.sensor_gain_error[k] = q[at::SENSOR_GAIN];
    }
    if let Some(a) = form.coupling {
        fx.orientation_coupling = [q[at::COUPLING1], q[at::COUPLING2]];
        fx.orientation_axis_body = std::array::from_fn(|k| if k == a { 1.0 } else { 0.0 });
    }
    if let Some(k) = form.air_path {
        fx.air_path_tau_s[k] = tau(at::AIR_PATH_TAU);
    }
    if form.conductance {
        fx.case_conductance_per_c = q[at::CONDUCTANCE];
    }
    c.effects = fx;
    c
}
