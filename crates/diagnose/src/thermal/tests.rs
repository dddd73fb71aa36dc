//! The identification on units that are not the twin: linear networks
//! of two to four nodes in forms the fitted one does not have (a block
//! carrying both sensors, a heat sink hanging off the case, a second
//! path from the air to the blocks), integrated here by their own
//! exact discretisation, read through offset, noisy, quantised sensors
//! and a chamber sensor with a gain error, with rows missing.

use super::floor::{median_abs, resolution};
use super::*;
use crate::analysis::series::Interval;
use crate::data::Sample;
use crate::geometry::Orientation;
use crate::twin::thermal::ThermalNetwork;
use nalgebra::DMatrix;
use rand::{RngExt, SeedableRng};
use rand_distr::StandardNormal;
use rand_xoshiro::Xoshiro256PlusPlus;

/// A linear network: `C dT/dt = G_air (air - T) + sum G_ij (T_j - T_i)
/// + Q`, with the sensors on nodes.
#[derive(Clone)]
struct Unit {
    /// Per node: capacitance (s per unit conductance), conductance to
    /// the air, heat input (degC per unit conductance).
    cap: Vec<f64>,
    to_air: Vec<f64>,
    heat: Vec<f64>,
    /// Symmetric conductances between nodes.
    links: Vec<(usize, usize, f64)>,
    /// Node of T1, T2, TK.
    sensors: [usize; 3],
    offsets: [f64; 3],
    noise_c: f64,
    lsb_c: f64,
    /// Chamber reading = gain * air + bias.
    air_gain: f64,
    air_bias: f64,
    /// Convection: link `.0`'s conductance times `1 + .1` while the
    /// sensitive axis is horizontal.
    convection: Option<(usize, f64)>,
    /// Nothing recorded before this time in the run at one
    /// temperature (an orientation run whose records begin after its
    /// warm-up), s.
    flat_from_s: usize,
    /// That run turns through the study's nine positions (four
    /// azimuths axis up, four rolls axis horizontal, 55 deg), not four
    /// azimuths each way.
    study_positions: bool,
}

fn draw_unit(seed: u64) -> Unit {
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed);
    let mut u = |lo: f64, hi: f64| lo + (hi - lo) * rng.random::<f64>();
    let log = |u: &mut dyn FnMut(f64, f64) -> f64, lo: f64, hi: f64| {
        (lo.ln() + (hi.ln() - lo.ln()) * u(0.0, 1.0)).exp()
    };
    let form = (seed % 4) as usize;
    // Node 0 is the case: time constant to the air 600..3000 s.
    let case_tau = log(&mut u, 600.0, 3000.0);
    let b1_tau = log(&mut u, 100.0, 2000.0);
    let b2_tau = log(&mut u, 100.0, 2000.0);
    let coupling = log(&mut u, 200.0, 20_000.0);
    let rise = |u: &mut dyn FnMut(f64, f64) -> f64| u(0.0, 5.0);
    let (cap, to_air, heat, links, sensors) = match form {
        // Two nodes: one block carries both block sensors.
        0 => (
            vec![case_tau, b1_tau],
            vec![1.0, 0.0],
            vec![rise(&mut u), rise(&mut u) / b1_tau],
            vec![(0, 1, 1.0)],
            [1, 1, 0],
        ),
        // Three nodes: the fitted form without convection.
        1 => (
            vec![case_tau, b1_tau, b2_tau],
            vec![1.0, 0.0, 0.0],
            vec![rise(&mut u), rise(&mut u) / b1_tau, rise(&mut u) / b2_tau],
            vec![(0, 1, 1.0), (0, 2, 1.0), (1, 2, b1_tau / coupling)],
            [1, 2, 0],
        ),
        // Four nodes: a heat sink on the case (a baseplate).
        2 => {
            let sink = log(&mut u, 300.0, 6000.0);
            let g = u(0.3, 2.0);
            (
                vec![case_tau, b1_tau, b2_tau, sink * g],
                vec![1.0, 0.0, 0.0, 0.0],
                vec![
                    rise(&mut u),
                    rise(&mut u) / b1_tau,
                    rise(&mut u) / b2_tau,
                    0.0,
                ],
                vec![
                    (0, 1, 1.0),
                    (0, 2, 1.0),
                    (1, 2, b1_tau / coupling),
                    (0, 3, g),
                ],
                [1, 2, 0],
            )
        }
        // Four nodes: a mount between the air and the case, and a weak
        // second path from the air to block 2.
        _ => {
            let mount = log(&mut u, 60.0, 1500.0);
            (
                vec![case_tau, b1_tau, b2_tau, mount],
                vec![0.0, 0.0, u(0.0, 0.05) * b2_tau / case_tau, 1.0],
                vec![
                    rise(&mut u),
                    rise(&mut u) / b1_tau,
                    rise(&mut u) / b2_tau,
                    0.0,
                ],
                vec![
                    (3, 0, case_tau / mount),
                    (0, 1, 1.0),
                    (0, 2, 1.0),
                    (1, 2, b1_tau / coupling),
                ],
                [1, 2, 0],
            )
        }
    };
    // Case heat as conductance-to-air units: a case rise of `heat[0]`.
    let offsets = [u(-0.3, 0.3), u(-0.3, 0.3), u(-0.3, 0.3)];
    let noise_c = log(&mut u, 0.005, 0.1);
    let lsb_c = log(&mut u, 0.005, 0.1);
    let air_gain = 1.0 + u(-0.05, 0.05);
    let air_bias = u(-0.5, 0.5);
    Unit {
        cap,
        to_air,
        heat,
        links,
        sensors,
        offsets,
        noise_c,
        lsb_c,
        air_gain,
        air_bias,
        convection: None,
        flat_from_s: 0,
        study_positions: false,
    }
}

/// A thermal cycle (soak, -40, +50, back) and a run at one temperature
/// with the orientation changing every 25 min: true air per second.
fn air_profiles() -> [Vec<f64>; 2] {
    let mut sp = Vec::new();
    let mut at: f64 = 20.0;
    for (target, hold_s) in [
        (20.0, 3600.0),
        (-40.0, 7200.0),
        (50.0, 7200.0),
        (20.0, 3600.0),
    ] {
        while (at - target).abs() > 1e-9 {
            at += (target - at).clamp(-1.0 / 60.0, 1.0 / 60.0);
            sp.push(at);
        }
        sp.extend(std::iter::repeat_n(at, hold_s as usize));
    }
    // The air trails the controller by 120 s.
    let mut air = 20.0;
    let cycle = sp
        .iter()
        .map(|&s| {
            air += (s - air) * (1.0 - (-1.0f64 / 120.0).exp());
            air
        })
        .collect();
    [cycle, vec![20.0; 9 * 1500]]
}

fn run_of(unit: &Unit, air: &[f64], seed: u64, name: &str) -> RunData {
    let flat = air.len() == 9 * 1500;
    // The share of the convection (the sensitive axis horizontal, as
    // 1 - |sin elevation|): 1 at the rolls, 0.43 at 55 deg.
    let horizontal = |t: usize| match (flat, (t / 1500) % 9) {
        (true, 4..8) => 1,
        (true, 8) if unit.study_positions => 2,
        (true, 8) => 1,
        _ => 0,
    };
    let gain = unit.convection.map_or(0.0, |c| c.1);
    let maps = [
        1.0,
        1.0 + gain,
        1.0 + gain * (1.0 - 35f64.to_radians().sin()),
    ]
    .map(|f| {
        let mut u = unit.clone();
        if let Some((link, _)) = unit.convection {
            u.links[link].2 *= f;
        }
        step_map(&u)
    });
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed);
    // Soaked, unpowered, then powered at t = 0.
    let mut x = nalgebra::DVector::<f64>::from_element(unit.cap.len(), air[0]);
    let mut samples = Vec::new();
    for (t, &air_c) in air.iter().enumerate() {
        let u = nalgebra::DVector::from_vec(vec![air_c, 1.0]);
        let (phi, gamma) = &maps[horizontal(t)];
        x = phi * &x + gamma * u;
        let record = t / 3600;
        // A minute between records unrecorded, and rows lost at random.
        if t % 3600 < 60 || rng.random::<f64>() < 0.002 || (flat && t < unit.flat_from_s) {
            continue;
        }
        let mut read = |k: usize| {
            let v = x[unit.sensors[k]]
                + unit.offsets[k]
                + unit.noise_c * rng.sample::<f64, _>(StandardNormal);
            (v / unit.lsb_c).round() * unit.lsb_c
        };
        let (t1, t2, tk) = (read(0), read(1), read(2));
        let position = (t / 1500) % 9;
        let orientation = if flat && unit.study_positions {
            match position {
                0..4 => Orientation::new(90.0 * position as f64, 90.0, 0.0),
                4..8 => Orientation::new(90.0, 0.0, 90.0 * (position - 4) as f64),
                _ => Orientation::new(90.0, 35.0, 0.0),
            }
        } else if flat {
            Orientation::new(
                90.0 * (position % 4) as f64,
                if position < 4 { 90.0 } else { 0.0 },
                0.0,
            )
        } else {
            Orientation::new(0.0, 90.0, 0.0)
        };
        samples.push(Sample {
            iv: Interval {
                time_s: t as f64 + 0.5,
                rate_dph: 0.0,
                reference_dph: 0.0,
                t1_c: t1,
                t2_c: t2,
                tcase_c: tk,
                chamber_c: unit.air_gain * air_c + unit.air_bias,
                frames: 400,
            },
            orientation,
            record: format!("r{record}"),
            step: format!("s{record}").into(),
            table_rate_body_dph: nalgebra::Vector3::zeros(),
        });
    }
    RunData {
        name: name.to_owned(),
        site: TwinConfig::default_rl16().site,
        samples,
    }
}

/// The unit's exact one-second map: the state's and the inputs' (air,
/// power) matrices.
fn step_map(unit: &Unit) -> (DMatrix<f64>, DMatrix<f64>) {
    let n = unit.cap.len();
    let mut a = DMatrix::<f64>::zeros(n, n);
    let mut b = DMatrix::<f64>::zeros(n, 2);
    for i in 0..n {
        a[(i, i)] -= unit.to_air[i] / unit.cap[i];
        b[(i, 0)] = unit.to_air[i] / unit.cap[i];
        b[(i, 1)] = unit.heat[i] / unit.cap[i];
    }
    // The case's heat is a rise above its air coupling.
    b[(0, 1)] = unit.heat[0] / unit.cap[0];
    for &(i, j, g) in &unit.links {
        a[(i, i)] -= g / unit.cap[i];
        a[(i, j)] += g / unit.cap[i];
        a[(j, j)] -= g / unit.cap[j];
        a[(j, i)] += g / unit.cap[j];
    }
    let mut m = DMatrix::<f64>::zeros(n + 2, n + 2);
    m.view_mut((0, 0), (n, n)).copy_from(&a);
    m.view_mut((0, n), (n, 2)).copy_from(&b);
    let e = m.exp();
    (
        e.view((0, 0), (n, n)).into_owned(),
        e.view((0, n), (n, 2)).into_owned(),
    )
}

fn within_bounds(c: &ThermalConfig) -> bool {
    let taus = [
        (c.case_tau_s, SHAPE[1]),
        (c.block1_tau_s, SHAPE[2]),
        (c.block2_tau_s, SHAPE[3]),
        (c.coupling_tau_s, SHAPE[4]),
    ];
    taus.iter().all(|(v, (_, lo, hi))| (*lo..=*hi).contains(v))
        && (c.mount_tau_s == 0.0 || (SHAPE[0].1..=SHAPE[0].2).contains(&c.mount_tau_s))
        && (c.sink_tau_s == 0.0 || (SHAPE[8].1..=SHAPE[8].2).contains(&c.sink_tau_s))
        && (SHAPE[9].1..=SHAPE[9].2).contains(&c.sink_capacity_ratio)
        && (SHAPE[10].1..=SHAPE[10].2).contains(&c.block_capacity_1_over_2)
        && (SHAPE[5].1..=SHAPE[5].2).contains(&c.convection_gain)
        && c.block_capacity_ratio
            .iter()
            .zip(&SHAPE[6..])
            .all(|(v, (_, lo, hi))| (*lo..=*hi).contains(v))
        && [c.case_rise_c, c.block1_rise_c, c.block2_rise_c]
            .iter()
            .all(|r| (0.0..=RISE_MAX_C).contains(r))
        && (AIR_GAIN.0..=AIR_GAIN.1).contains(&c.air_gain)
}

/// The two runs of a unit.
fn runs_of(seed: u64) -> [RunData; 2] {
    let [cycle, flat] = air_profiles();
    let unit = draw_unit(seed);
    [
        run_of(&unit, &cycle, seed * 2, "cycle"),
        run_of(&unit, &flat, seed * 2 + 1, "flat"),
    ]
}

#[test]
fn a_block_as_one_map_is_the_block_stepped() {
    let mut q = shape_of(&TwinConfig::default_rl16().thermal);
    (
        q[at::MOUNT_TAU],
        q[at::RATIO1],
        q[at::SINK_TAU],
        q[at::SINK_RATIO],
        q[at::BLOCKS_1_OVER_2],
    ) = (300f64.ln(), 0.4, 2000f64.ln(), 1.5, 0.5f64.ln());
    let form = Form {
        full: true,
        ..Form::default()
    };
    let layout = form.layout(true);
    let key = Key {
        convection: 1.3,
        coupling: 0.0,
        air_c: twin_effects::CONDUCTANCE_REFERENCE_C,
    };
    let (phi, gamma) = discretize::<5, 9>(&q, &form, &layout, &key, STEP_S);
    let air = [20.0, 21.5, 23.0, 22.0, 19.0, 18.5];
    let mut x = Nodes::<5>::from_fn(|i, j| (i * 4 + j) as f64 * 0.1 + 15.0);
    let mut stepped = x;
    let mut acc = Nodes::<5>::zeros();
    for &a in &air {
        let before = stepped;
        let mut u = gamma;
        u.column_mut(0).scale_mut(a);
        stepped = phi * stepped + u;
        acc += (before + stepped) * (0.5 / air.len() as f64);
    }
    let mean = BlockStep::new(&phi, &gamma, &layout.sensors).apply(&mut x, &air);
    assert!((x - stepped).abs().max() < 1e-9, "{x} vs {stepped}");
    for (s, node) in layout.sensors.iter().enumerate() {
        for j in 0..4 {
            assert!((mean[s][j] - acc[(*node, j)]).abs() < 1e-9);
        }
    }
}

/// A step's transition and input matrices, from the nodes' exponential
/// and one solve, are the augmented matrix's exponential's blocks at the
/// twin's network and at the corners of the search's box where the
/// slowest mode is slowest (heavy blocks and sink, the longest time
/// constants: the solve's subtraction loses most there, 4e-13 measured)
/// and fastest (the shortest), with a lagging sensor and an air path, and
/// over a step 10 times the usual.
#[test]
fn a_step_from_the_nodes_alone_is_the_augmented_exponential() {
    let base = shape_of(&TwinConfig::default_rl16().thermal);
    let corner = |pick: &dyn Fn(usize) -> f64| {
        let mut q = base;
        for (i, v) in q.iter_mut().enumerate().take(BASE_LEN) {
            *v = pick(i);
        }
        q[at::LAG_TAU] = pick(at::LAG_TAU);
        q[at::AIR_PATH_TAU] = pick(at::AIR_PATH_TAU);
        q
    };
    let bound = |i: usize, hi: bool| {
        let v = if hi { SHAPE[i].2 } else { SHAPE[i].1 };
        if LOG_SCALED.contains(&i) { v.ln() } else { v }
    };
    let slow = corner(&|i| bound(i, i != at::CONVECTION));
    let fast = corner(&|i| bound(i, i == at::RATIO1 || i == at::RATIO2 || i == at::SINK_RATIO));
    let form = Form {
        full: true,
        lag: Some(0),
        air_path: Some(1),
        ..Form::default()
    };
    let layout = form.layout(true);
    let key = Key {
        convection: 1.3,
        coupling: 0.0,
        air_c: twin_effects::CONDUCTANCE_REFERENCE_C,
    };
    for (name, q) in [("twin", base), ("slow corner", slow), ("fast corner", fast)] {
        for dt in [STEP_S, 10.0 * STEP_S] {
            let (phi, gamma) = discretize::<6, 10>(&q, &form, &layout, &key, dt);
            let e = (rates::<6, 10>(&q, &form, &layout, &key) * dt).exp();
            let (phi_aug, gamma_aug) = (
                e.fixed_view::<6, 6>(0, 0).into_owned(),
                e.fixed_view::<6, INPUTS>(0, 6).into_owned(),
            );
            let worst = |a: &SMatrix<f64, 6, 6>, b: &SMatrix<f64, 6, 6>| (a - b).abs().max();
            assert!(
                worst(&phi, &phi_aug) < 1e-13,
                "{name}, dt {dt}: {phi} vs {phi_aug}"
            );
            let scale = gamma_aug.abs().max();
            let off = (gamma - gamma_aug).abs().max();
            assert!(
                off < 1e-11 * scale.max(1e-300),
                "{name}, dt {dt}: {gamma} vs {gamma_aug}"
            );
        }
    }
}

#[test]
fn the_fitted_form_is_the_twins_network() {
    // What the fit simulates for a network is what the twin makes of it
    // (mount node, air gain, offsets, blocks loading the case, a heat
    // sink, convection), so twin-updated.toml carries the fitted unit.
    let mut cfg = TwinConfig::default_rl16().thermal;
    cfg.mount_tau_s = 300.0;
    cfg.air_gain = 1.02;
    cfg.block_capacity_ratio = [0.4, 0.2];
    cfg.sensor_offset_c = [0.1, -0.2, 0.05];
    cfg.convection_gain = 0.8;
    let (lin, worst) = fit_of_twin(&cfg);
    assert!(worst < 0.01, "worst block {worst} degC");
    let fitted = to_config(&cfg, &shape_of(&cfg), &form_of(&cfg), &lin);
    assert!((fitted.air_gain - 1.02).abs() < 1e-3, "{fitted:?}");
    assert!(
        (fitted.case_rise_c - cfg.case_rise_c).abs() < 0.02,
        "{fitted:?}"
    );
    for k in 0..3 {
        let off = fitted.sensor_offset_c[k] - cfg.sensor_offset_c[k];
        assert!(off.abs() < 0.02, "{fitted:?}");
    }
    // A heat sink on the case, blocks of unequal capacity: the
    // response is the twin's (the case
    // rise alone comes out 0.04 degC high on this one cycle, the sink
    // stretching the warm-up that tells it from the offset and the
    // gain).
    // Blocks of unequal capacity too.
    cfg.sink_tau_s = 2500.0;
    cfg.sink_capacity_ratio = 1.5;
    cfg.block_capacity_1_over_2 = 4.0;
    let (lin, worst) = fit_of_twin(&cfg);
    assert!(worst < 0.01, "in the full form: worst block {worst} degC");
    let fitted = to_config(&cfg, &shape_of(&cfg), &form_of(&cfg), &lin);
    assert!(
        (fitted.sink_tau_s - 2500.0).abs() < 1e-6
            && fitted.sink_capacity_ratio == 1.5
            && (fitted.block_capacity_1_over_2 - 4.0).abs() < 1e-9,
        "{fitted:?}"
    );
    // The case's conductance changing with the air (the thermal effect
    // `conductance_temperature`, 1 % per degC: a conductance 0.4 to 1.3
    // times the reference's over the cycle): the fit's maps, taken on a
    // 5 degC air grid and interpolated, follow the twin, which steps the
    // exact conductance every 0.1 s. Worst block 0.022 degC, the same on a
    // grid ten times finer (0.0221): the rest is the block's mean air
    // standing for each step's while the air ramps.
    cfg.effects.case_conductance_per_c = 0.01;
    let (_, worst) = fit_of_twin(&cfg);
    assert!(
        worst < 0.03,
        "with the conductance: worst block {worst} degC"
    );
}

/// The twin's network `cfg` through the thermal cycle of
/// [`air_profiles`], the sensitive axis up in its first half and
/// horizontal north in its second (a record each), read without noise.
/// (The RL-16's sensor axis, body y, is horizontal at both: its
/// convection is not exercised.)
fn twin_run(cfg: &ThermalConfig) -> RunData {
    let [cycle, _] = air_profiles();
    let mut net = ThermalNetwork::soaked(cfg, cycle[0]);
    let mut samples = Vec::new();
    for (t, &air) in cycle.iter().enumerate() {
        let up = t >= cycle.len() / 2;
        let orientation = Orientation::new(0.0, if up { 0.0 } else { 90.0 }, 0.0);
        let g = (orientation.rotation().inverse() * crate::geometry::gravity_ned_g())
            .dot(&Vector3::from(cfg.sensor_axis_body).normalize())
            .abs();
        for _ in 0..10 {
            net.step(0.1, air, true, 1.0 + cfg.convection_gain * g);
        }
        let [t1_c, t2_c, tcase_c] = net.readings_c();
        samples.push(Sample {
            iv: Interval {
                time_s: t as f64 + 0.5,
                rate_dph: 0.0,
                reference_dph: 0.0,
                t1_c,
                t2_c,
                tcase_c,
                chamber_c: air,
                frames: 400,
            },
            orientation,
            // The table turns between records.
            record: if up { "r2" } else { "r1" }.into(),
            step: "s".into(),
            table_rate_body_dph: nalgebra::Vector3::zeros(),
        });
    }
    RunData {
        name: "twin".into(),
        site: TwinConfig::default_rl16().site,
        samples,
    }
}

/// [`twin_run`] as the fit's 60 s blocks.
fn twin_blocks(cfg: &ThermalConfig) -> Vec<Vec<Block>> {
    blocks(
        &[twin_run(cfg)],
        Vector3::from(cfg.sensor_axis_body).normalize(),
    )
}

/// The twin's network `cfg` through a thermal cycle ([`twin_run`]),
/// fitted at its own shape: the linear
/// quantities and the worst block residual after the first, degC.
fn fit_of_twin(cfg: &ThermalConfig) -> (Linear, f64) {
    let data = twin_blocks(cfg);
    let cost = Cost {
        runs: &data,
        held_out: None,
        form: Form {
            full: true,
            ..form_of(cfg)
        },
    };
    let (lin, res) = cost.fit_at(&shape_of(cfg));
    // (The first minute, where the blocks start from the soak, differs
    // by a few hundredths: the twin steps every 0.1 s, the fit every
    // 10 s.)
    let worst = res[0]
        .iter()
        .skip(1)
        .flat_map(|r| r.iter().map(|v| v.abs()))
        .fold(0.0, f64::max);
    (lin, worst)
}

#[test]
fn units_of_other_network_forms_are_followed_and_never_get_an_unphysical_network() {
    // One unit of each form: two nodes, three with unequal block
    // capacities, a heat sink on the case, a mount and a second path;
    // and a unit whose small block exchanges heat fast with a large one.
    for seed in [0, 1, 2, 3, 17] {
        let runs = runs_of(seed);
        let layer = layer(&runs, None, false);
        let net_gap = layer.fitted_gap_c.expect("the network is always fitted");
        assert_eq!(layer.form_misfit.is_some(), net_gap > FORM_MISFIT_C);
        if let Some(n) = &layer.fitted {
            assert!(within_bounds(n), "seed {seed}: {n:?}");
        }
        assert!(layer.gap_c < FORM_MISFIT_C, "seed {seed}: {}", layer.gap_c);
        // A network that cannot follow is not returned, and where it
        // misses is said.
        assert_eq!(layer.fitted.is_some(), layer.form_misfit.is_none());
        if let Some(m) = &layer.form_misfit {
            assert!(m.gap_c > FORM_MISFIT_C && !m.r#where.is_empty());
            assert!(m.modal_gap_c < FORM_MISFIT_C);
        }
        // The baseplate: a network without a sink does not follow it
        // (`form_misfit`); with one it does.
        // The search settles it: with plain Levenberg-Marquardt steps
        // (no geodesic acceleration) its fit on all the runs ended at
        // 0.0126 degC, with them 0.0093.
        if seed == 2 {
            let n = layer.fitted.as_ref().expect("the sink's network follows");
            assert!(n.sink_tau_s > 0.0 && n.sink_capacity_ratio > 0.0, "{n:?}");
            assert!(net_gap < 0.011, "seed 2: {net_gap}");
        }
        // Blocks of 1380 s and 110 s on one conductance (block 1 13
        // times block 2: exchange time constants of 3400 s and 270 s):
        // a network whose blocks exchange with one time constant missed
        // by 0.075 degC held out; the full form follows (it finds block
        // 1 about 12 times block 2).
        if seed == 17 {
            let n = layer.fitted.as_ref().expect("unequal blocks follow");
            assert!(n.block_capacity_1_over_2 > 8.0, "{n:?}");
        }
    }
}

/// A unit whose convection follows the sensitive axis (a block's
/// conductance to the case a fifth higher while the axis is
/// horizontal: not the twin's sensor axis, not its block coupling),
/// its run at one temperature recorded only from 35 min on, as an
/// imported orientation run is. With the convection input on the
/// twin's sensor axis the modal model missed such units by 0.1-0.15
/// degC held out, and with the warm-up's first minutes held out it
/// missed them even without convection (by up to 0.6 degC in the
/// warm-up).
#[test]
fn convection_along_another_axis_and_records_after_the_warm_up_are_followed() {
    for seed in [4, 5] {
        let [cycle, flat] = air_profiles();
        let mut unit = draw_unit(seed);
        // Block 1 4 degC above the case when powered.
        unit.heat[1] = 4.0;
        unit.convection = Some((0, 0.2));
        unit.flat_from_s = 2100;
        unit.study_positions = true;
        let runs = [
            run_of(&unit, &cycle, seed * 2, "cycle"),
            run_of(&unit, &flat, seed * 2 + 1, "flat"),
        ];
        let layer = layer(&runs, None, false);
        assert!(layer.gap_c < FORM_MISFIT_C, "seed {seed}: {}", layer.gap_c);
        if let Some(n) = &layer.fitted {
            assert!(within_bounds(n), "seed {seed}: {n:?}");
        }
    }
}

#[test]
#[ignore = "the measurement over 40 units; run with --release --ignored"]
fn independent_units_measured() {
    let base = TwinConfig::default_rl16().thermal;
    let mut gaps = Vec::new();
    for seed in 0..40u64 {
        let runs = runs_of(seed);
        let f = fitted_network(&runs, &base, false);
        let gap = quadratic_mean(&f.modal_per_sensor_c);
        println!(
            "seed {seed} form {} modal {gap:.4} network {:.4} modes {:?}",
            seed % 4,
            quadratic_mean(&f.network_per_sensor_c),
            f.modes_s.map(|t| t.round()),
        );
        assert!(within_bounds(&f.network), "{:?}", f.network);
        gaps.push(gap);
    }
    gaps.sort_by(f64::total_cmp);
    let below = gaps.iter().filter(|g| **g < FORM_MISFIT_C).count();
    println!(
        "median {:.4}, below {FORM_MISFIT_C}: {below}/{}",
        gaps[gaps.len() / 2],
        gaps.len()
    );
}

/// The floor the sensors leave: white noise of sigma at 1 Hz leaves
/// sigma / sqrt 60 in 60 s means; a 1/16 degC quantisation that the
/// noise does not dither leaves (1/16) / sqrt 12; a slow ramp under
/// either is not taken for noise.
#[test]
fn the_noise_floor_is_read_from_the_sensors_alone() {
    let run = |sigma: f64, q: f64, seed: u64| {
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed);
        let samples = (0..20_000)
            .map(|t| {
                // A ramp, a soak and a slow exponential: the signal a
                // model would follow.
                let tf = t as f64;
                let truth = 20.0 + 10.0 * (1.0 - (-tf / 3000.0).exp()) + 0.001 * tf.min(5000.0);
                let read = |rng: &mut Xoshiro256PlusPlus| {
                    let v = truth + sigma * rng.sample::<f64, _>(StandardNormal);
                    if q > 0.0 { (v / q).round() * q } else { v }
                };
                Sample {
                    iv: Interval {
                        time_s: tf + 0.5,
                        rate_dph: 0.0,
                        reference_dph: 0.0,
                        t1_c: read(&mut rng),
                        t2_c: read(&mut rng),
                        tcase_c: read(&mut rng),
                        chamber_c: 20.0,
                        frames: 400,
                    },
                    orientation: Orientation::new(0.0, 90.0, 0.0),
                    record: "r".into(),
                    step: "s".into(),
                    table_rate_body_dph: nalgebra::Vector3::zeros(),
                }
            })
            .collect();
        [RunData {
            name: "r".into(),
            site: TwinConfig::default_rl16().site,
            samples,
        }]
    };
    let (_, white) = noise_floor(&run(0.05, 0.0, 1));
    let want = 0.05 / 60f64.sqrt();
    assert!(
        (white / want - 1.0).abs() < 0.1,
        "white: {white} against {want}"
    );
    let (per, quantised) = noise_floor(&run(0.003, 0.0625, 2));
    let want = 0.0625 / 12f64.sqrt();
    assert!(
        (quantised / want - 1.0).abs() < 0.1,
        "quantised: {quantised} against {want} ({per:?})"
    );
    // Noise of twice the step dithers it: the floor is the noise's.
    let (_, dithered) = noise_floor(&run(0.125, 0.0625, 3));
    let want = (0.125f64.powi(2) + 0.0625f64.powi(2) / 12.0).sqrt() / 60f64.sqrt();
    assert!(
        (dithered / want - 1.0).abs() < 0.15,
        "dithered: {dithered} against {want}"
    );
    let (_, clean) = noise_floor(&run(0.0, 0.0, 4));
    assert!(clean < 1e-4, "a noiseless ramp: {clean}");
}

/// The twin's RL-16 network with a mount node and blocks that load
/// the case: the unit the recovery tests simulate.
fn known_unit() -> ThermalConfig {
    let mut cfg = TwinConfig::default_rl16().thermal;
    cfg.mount_tau_s = 300.0;
    cfg.block_capacity_ratio = [0.4, 0.2];
    cfg
}

/// Started a third of a log unit off in every time constant, the
/// search settles on the simulated network's time constants, at a
/// training cost no higher than the truth's (what the fit's 10 s step
/// leaves). (The convection is not checked: the twin's sensor axis, y,
/// stays horizontal at both of these positions.)
/// Units with thermal physics the network form does not have, each made
/// by the twin with one `[thermal.effects]` entry: the layer names that
/// effect (and on what), brings the held-out gap within its limit, and
/// writes the effect into the fitted network; the same unit without it
/// gets none.
#[test]
fn a_thermal_effect_the_form_lacks_is_named_and_none_where_there_is_none() {
    let plain = layer(&[twin_run(&known_unit())], None, false);
    assert!(plain.effects.is_empty(), "{:?}", plain.effects);
    assert!(
        plain.effect_candidates.is_empty(),
        "the network alone followed"
    );
    let mut cfg = known_unit();
    cfg.effects.case_conductance_per_c = 0.008;
    let with = layer(&[twin_run(&cfg)], None, false);
    let named: Vec<&str> = with.effects.iter().map(|e| e.name.as_str()).collect();
    assert_eq!(
        named.first(),
        Some(&"conductance_temperature"),
        "{:?}",
        with.effect_candidates
    );
    // The named candidate was ranked on its whole fit; the others, far
    // behind, on their screened or glanced fits.
    for c in &with.effect_candidates {
        let whole = c.name == "conductance_temperature";
        assert_eq!(c.in_sample_fit == Fit::Whole, whole, "{c:?}");
    }
    let e = &with.effects[0];
    let per_c = e.parameters["case_conductance_per_c"];
    assert!((per_c / 0.008 - 1.0).abs() < 0.25, "{per_c}");
    assert!(
        e.held_out_gap_before_c > FORM_MISFIT_C && e.shrink > 0.5,
        "{e:?}"
    );
    assert!(with.form_misfit.is_none(), "{:?}", with.form_misfit);
    // The reference says the network it is carries the effect.
    assert!(
        with.reference
            .contains("with the thermal effect conductance_temperature"),
        "{}",
        with.reference
    );
    let fitted = with
        .fitted
        .as_ref()
        .expect("the network with its effect follows");
    assert!((fitted.effects.case_conductance_per_c - per_c).abs() < 1e-12);
}

#[test]
fn the_network_search_recovers_the_simulating_networks_time_constants() {
    let cfg = known_unit();
    let data = twin_blocks(&cfg);
    let truth = shape_of(&cfg);
    let mut start = truth;
    for (k, i) in LOG_SCALED[..5].iter().enumerate() {
        start[*i] += if k % 2 == 0 { 0.3 } else { -0.3 };
    }
    start[at::CONVECTION] = 0.2;
    let q = search_shape(&data, None, Form::default(), &[start], 1, 150);
    let close = |i: usize, within: f64| {
        let (got, want) = (q[i].exp(), truth[i].exp());
        assert!(
            (got / want - 1.0).abs() < within,
            "{}: {got} against {want}",
            SHAPE[i].0
        );
    };
    close(at::CASE_TAU, 0.02);
    close(at::BLOCK1_TAU, 0.05);
    close(at::BLOCK2_TAU, 0.05);
    close(at::MOUNT_TAU, 0.1);
    close(at::COUPLING_TAU, 0.1);
    let cost = simple_form(&data);
    let at_truth = cost.cost(&cost.searched(&truth)).expect("a cost");
    let found = cost.cost(&cost.searched(&q)).expect("a cost");
    assert!(found <= 1.01 * at_truth, "{found} against {at_truth}");
}

/// A case slower than the bounds allow (a 20 h time constant): the
/// search ends within its bounds, the case near its own.
#[test]
fn the_search_stays_within_its_bounds() {
    let mut cfg = known_unit();
    cfg.case_tau_s = 72_000.0;
    let data = twin_blocks(&cfg);
    let q = search_shape(
        &data,
        None,
        Form::default(),
        &[shape_of(&known_unit())],
        1,
        150,
    );
    assert_eq!(clamp_shape(&q).1, 0.0, "{q:?}");
    let cost = simple_form(&data);
    let (lin, _) = cost.fit_at(&q);
    assert!(within_bounds(&to_config(&cfg, &q, &Form::default(), &lin)));
    let case = q[at::CASE_TAU].exp();
    assert!(case > 0.5 * SHAPE[at::CASE_TAU].2, "{case}");
}

/// A chamber sensor reading half again the air: the linear solve holds
/// the air gain on its bound and solves the rest again.
#[test]
fn the_air_gain_is_held_on_its_bound() {
    let mut cfg = known_unit();
    cfg.air_gain = 1.5;
    let (lin, _) = cost_at(&cfg);
    assert_eq!(lin[0], AIR_GAIN.1, "{lin:?}");
    assert!(
        lin[1..4].iter().all(|r| (0.0..=RISE_MAX_C).contains(r)),
        "{lin:?}"
    );
    // Within its bounds the gain is the unit's.
    cfg.air_gain = 1.1;
    let (lin, _) = cost_at(&cfg);
    assert!((lin[0] - 1.1).abs() < 1e-3, "{lin:?}");
}

/// The linear quantities and residuals of the twin's network `cfg`
/// fitted at its own shape (the simpler form).
fn cost_at(cfg: &ThermalConfig) -> (Linear, Vec<Vec<[f64; 3]>>) {
    simple_form(&twin_blocks(cfg)).fit_at(&shape_of(cfg))
}

/// The simpler form's cost on every block of `data`.
fn simple_form(data: &[Vec<Block>]) -> Cost<'_> {
    Cost {
        runs: data,
        held_out: None,
        form: Form::default(),
    }
}

/// Within bounds a shape is kept as it is; past one, it is clamped and
/// the distance (in the searched, log units) is the penalty.
#[test]
fn a_shape_is_clamped_into_its_bounds_with_the_distance_as_penalty() {
    let q = shape_of(&known_unit());
    assert_eq!(clamp_shape(&q), (q, 0.0));
    let mut past = q;
    past[at::CASE_TAU] = SHAPE[at::CASE_TAU].2.ln() + 0.5;
    past[at::CONVECTION] = -0.25;
    let (c, outside) = clamp_shape(&past);
    assert_eq!(c[at::CASE_TAU], SHAPE[at::CASE_TAU].2.ln());
    assert_eq!(c[at::CONVECTION], 0.0);
    assert!((outside - (0.25 + 0.0625)).abs() < 1e-12, "{outside}");
    // And the twin's configuration round-trips through a shape.
    let back = to_config(
        &known_unit(),
        &q,
        &Form::default(),
        &[1.0, 1.5, 6.0, 4.0, 0.0, 0.0, 0.0],
    );
    let cfg = known_unit();
    for (a, b) in [
        (back.case_tau_s, cfg.case_tau_s),
        (back.block1_tau_s, cfg.block1_tau_s),
        (back.coupling_tau_s, cfg.coupling_tau_s),
        (back.mount_tau_s, cfg.mount_tau_s),
    ] {
        assert!((a / b - 1.0).abs() < 1e-12, "{a} against {b}");
    }
}

/// 60 s blocks never span a record change or a missing second; the
/// first 10 min are in every fold's training, the rest cut into
/// contiguous quarters, the first quarter of run r held out in fold r.
#[test]
fn blocks_are_whole_minutes_of_one_record_in_contiguous_folds() {
    let mut run = twin_run(&known_unit());
    run.samples.truncate(6000);
    // A second missing at 3000 s; the record changes at 4530 s.
    run.samples.remove(3000);
    for s in &mut run.samples {
        s.record = if s.iv.time_s < 4530.0 { "a" } else { "b" }.into();
    }
    let runs = [run.clone(), run];
    let data = blocks(&runs, Vector3::y());
    for (r, b) in data.iter().enumerate() {
        for x in b {
            assert_eq!(x.end_s - x.start_s, AVERAGING_S as f64);
            let spans = |t: f64| x.start_s < t && t < x.end_s;
            assert!(
                !spans(3000.5) && !spans(4530.0),
                "{} {}",
                x.start_s,
                x.end_s
            );
            if x.start_s < PINNED_S {
                assert_eq!(x.fold, PINNED);
            } else {
                assert!(x.fold < FOLDS);
            }
        }
        // Folds change in order (one quarter after another, cyclic).
        let folds: Vec<usize> = b.iter().map(|x| x.fold).filter(|&f| f != PINNED).collect();
        let changes = folds.windows(2).filter(|w| w[0] != w[1]).count();
        assert_eq!(changes, FOLDS - 1, "run {r}: {folds:?}");
        assert!(
            b.iter()
                .all(|x| x.fold != (r + FOLDS - 1) % FOLDS || x.start_s > 2000.0)
        );
    }
    assert_ne!(
        data[0].last().map(|b| b.fold),
        data[1].last().map(|b| b.fold)
    );
}

/// The twin's network driven by the measured air of runs it made
/// itself leaves no gap; a unit whose case is twice as slow does.
#[test]
fn the_twin_reproduces_its_own_runs_and_not_another_units() {
    let twin = TwinConfig::default_rl16();
    let made_by = |cfg: &ThermalConfig| {
        let [cycle, _] = air_profiles();
        let axis = Vector3::from(cfg.sensor_axis_body).normalize();
        let mut net = ThermalNetwork::soaked(cfg, cycle[0]);
        let orientation = Orientation::new(0.0, 0.0, 0.0);
        let g = (orientation.rotation().inverse() * crate::geometry::gravity_ned_g())
            .dot(&axis)
            .abs();
        let samples: Vec<Sample> = cycle
            .iter()
            .take(20_000)
            .enumerate()
            .map(|(t, &air)| {
                let time_s = t as f64 + 0.5;
                net.step(
                    if t == 0 { 0.5 } else { 1.0 },
                    air,
                    true,
                    1.0 + cfg.convection_gain * g,
                );
                Sample {
                    iv: Interval {
                        time_s,
                        rate_dph: 0.0,
                        reference_dph: 0.0,
                        t1_c: net.t1_c,
                        t2_c: net.t2_c,
                        tcase_c: net.case_c,
                        chamber_c: air,
                        frames: 400,
                    },
                    orientation,
                    record: "r".into(),
                    step: "s".into(),
                    table_rate_body_dph: nalgebra::Vector3::zeros(),
                }
            })
            .collect();
        [RunData {
            name: "made".into(),
            site: twin.site,
            samples,
        }]
    };
    let own = layer(&made_by(&twin.thermal), Some(&twin), false);
    assert!(own.gap_c < 1e-9, "{}", own.gap_c);
    assert!(own.fitted.is_none() && own.fitted_gap_c.is_none());
    assert_eq!(own.series[0].len(), 20_000 / AVERAGING_S);
    let mut slower = twin.thermal.clone();
    slower.case_tau_s *= 2.0;
    let other = layer(&made_by(&slower), Some(&twin), false);
    assert!(other.gap_c > 0.1, "{}", other.gap_c);
}

/// A quantised sensor's step is read from the steps between samples;
/// a sensor that is not quantised (or whose steps are not multiples of
/// the smallest) has none.
#[test]
fn a_sensors_resolution_is_its_smallest_whole_step() {
    let q = 0.0625;
    let steps: Vec<f64> = (1..50).map(|k| q * f64::from(k % 4 + 1)).collect();
    assert_eq!(resolution(&steps), q);
    let mut odd = steps.clone();
    odd.extend((0..20).map(|k| q * (1.37 + 0.1 * f64::from(k))));
    assert_eq!(resolution(&odd), 0.0);
    assert_eq!(resolution(&[]), 0.0);
    assert_eq!(median_abs(&mut [-3.0, 1.0, -2.0]), Some(2.0));
    assert_eq!(median_abs(&mut []), None);
}

/// The two workers' results come back in the jobs' order.
#[test]
fn work_on_two_threads_keeps_the_jobs_order() {
    let jobs: Vec<u64> = (0..9).collect();
    let out = on_two_threads(&jobs, |&j| j * j);
    assert_eq!(out, jobs.iter().map(|j| j * j).collect::<Vec<_>>());
    assert!(on_two_threads(&[] as &[u64], |&j| j).is_empty());
}
