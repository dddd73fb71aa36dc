//! Every driver against its simulator, over loopback TCP and a real pty,
//! with the simulators' fault injection. Here, beside the drivers, since
//! they are the crate's own: the rest of the crate and other programs reach
//! the devices through the traits and `bench::open_bench`.

use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::time::Duration;

use crate::driver::acl::AclTable;
use crate::driver::espec::EspecChamber;
use crate::driver::gyro::GyroReader;
use crate::driver::link::{Connector, LineLink};
use crate::driver::supply::ScpiSupply;
use crate::driver::watlow::WatlowChamber;
use crate::driver::{
    Chamber, ChamberMode, DeviceError, InPosition, MotionTable, PowerSupply, RetryPolicy,
    SupplyReading,
};
use crate::geometry::TableAngles;
use crate::protocol::frame::FrameLayout;
use crate::protocol::supply::Dialect;
use crate::sim::serve::{Serve, Served, start};
use crate::transport::{BoxTransport, DeviceSpec, open};

const POLICY: RetryPolicy = RetryPolicy {
    timeout: Duration::from_millis(300),
    attempts: 3,
    reconnect_window: Duration::from_secs(3),
};

/// The simulated bench with its unit powered from the start (these tests
/// read the gyro's link, not its power-on).
async fn serve(speed: f64) -> Served {
    let mut s = Serve::load(None).expect("defaults");
    s.config.speed = speed;
    s.config.unit_powered = true;
    start(&s).await.expect("simulated bench starts")
}

fn spec(served: &Served, device: &str, protocol: &str, scheme: &str) -> DeviceSpec {
    served
        .endpoints
        .iter()
        .find(|e| e.device == device && e.protocol == protocol && e.address.starts_with(scheme))
        .expect("endpoint served")
        .address
        .parse()
        .expect("valid spec")
}

async fn connect(spec: &DeviceSpec) -> BoxTransport {
    open(spec, Duration::from_secs(2))
        .await
        .expect("transport opens")
}

fn connector(spec: DeviceSpec) -> Connector {
    Arc::new(move || {
        let spec = spec.clone();
        Box::pin(async move { open(&spec, Duration::from_secs(2)).await })
    })
}

async fn espec(served: &Served, scheme: &str) -> EspecChamber {
    let s = spec(served, "chamber", "espec-ascii", scheme);
    let t = connect(&s).await;
    EspecChamber::new(
        LineLink::new("chamber", t, Some(connector(s)), POLICY),
        None,
    )
}

async fn acl(served: &Served, scheme: &str) -> AclTable {
    let s = spec(served, "table", "acl", scheme);
    let t = connect(&s).await;
    AclTable::new(LineLink::new("table", t, Some(connector(s)), POLICY))
}

async fn supply(served: &Served, dialect: Dialect, scheme: &str) -> ScpiSupply {
    let s = spec(served, "supply", dialect.as_str(), scheme);
    let t = connect(&s).await;
    ScpiSupply::new(
        LineLink::new("supply", t, Some(connector(s)), POLICY),
        dialect,
    )
}

/// Read channel 2 until `done` holds (2 s at most); the last reading.
async fn supply_until(p: &mut ScpiSupply, done: impl Fn(&SupplyReading) -> bool) -> SupplyReading {
    let mut last = None;
    for _ in 0..100 {
        let r = p.read(2).await.expect("a reading");
        if done(&r) {
            return r;
        }
        last = Some(r);
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    panic!("the supply never got there: {last:?}");
}

/// Power the unit on channel 2, trip the protection by lowering the limit
/// under its steady draw, see the refusal to switch a tripped output on,
/// clear it and power the unit again: through the real driver. A Rigol
/// trips at once, so its limit must clear the turn-on inrush (1.15 A); a
/// Keysight rides it out in current limit for less than its delay.
async fn supply_cycle(p: &mut ScpiSupply) {
    let limit = match p.dialect() {
        Dialect::KeysightE36300 => 1.0,
        Dialect::RigolDp800 => 1.5,
    };
    p.configure(2, 15.0, limit, true)
        .await
        .expect("settings taken");
    p.output(2, true).await.expect("output on");
    // The inrush, then the steady 0.55 A.
    let on = supply_until(p, |r| r.on && (r.v - 15.0).abs() < 0.01 && r.a < 0.551).await;
    assert!((on.a - 0.55).abs() < 0.001 && !on.tripped, "{on:?}");
    p.configure(2, 15.0, 0.5, true)
        .await
        .expect("settings taken");
    let tripped = supply_until(p, |r| r.tripped).await;
    assert!(!tripped.on && tripped.a == 0.0, "{tripped:?}");
    let e = p
        .output(2, true)
        .await
        .expect_err("a tripped output stays off");
    assert!(e.to_string().contains("-221 Settings conflict"), "{e}");
    p.clear_trip(2).await.expect("cleared");
    p.configure(2, 15.0, limit, true)
        .await
        .expect("settings taken");
    p.output(2, true).await.expect("output on");
    supply_until(p, |r| r.on && r.a > 0.5).await;
    let e = p
        .configure(2, 99.0, limit, true)
        .await
        .expect_err("beyond the rating");
    assert!(e.to_string().contains("-222 Data out of range"), "{e}");
    p.output(2, false).await.expect("output off");
    supply_until(p, |r| !r.on && r.v == 0.0 && r.a == 0.0).await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn supply_driver_powers_the_unit_through_both_dialects_over_tcp_and_pty() {
    for dialect in Dialect::ALL {
        let mut s = Serve::load(None).expect("defaults");
        s.config.supply = dialect;
        let served = start(&s).await.expect("simulated bench starts");
        for scheme in ["tcp://", "pty://"] {
            let mut p = supply(&served, dialect, scheme).await;
            let id = p.identify().await.expect("identity");
            let model = match dialect {
                Dialect::KeysightE36300 => "E36312A",
                Dialect::RigolDp800 => "DP832",
            };
            assert!(
                id.model.as_deref().is_some_and(|m| m.contains(model)),
                "{id:?}"
            );
            supply_cycle(&mut p).await;
        }
    }
}

async fn chamber_round_trip(c: &mut dyn Chamber) {
    let r = c.read().await.expect("reading");
    assert_eq!(
        (r.air_c, r.set_point_c, r.mode),
        (20.0, 20.0, ChamberMode::Constant)
    );
    c.set_point(-10.0).await.expect("set point");
    c.set_mode(ChamberMode::Standby).await.expect("mode");
    let r = c.read().await.expect("reading");
    assert_eq!((r.set_point_c, r.mode), (-10.0, ChamberMode::Standby));
    assert!(r.alarms.is_empty());
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn espec_driver_against_its_simulator_over_tcp_and_pty() {
    let served = serve(1.0).await;
    for scheme in ["tcp://", "pty://"] {
        let mut c = espec(&served, scheme).await;
        chamber_round_trip(&mut c).await;
        c.set_mode(ChamberMode::Constant)
            .await
            .expect("back to constant");
        c.set_point(20.0).await.expect("back to 20");
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn watlow_driver_against_its_simulator_over_tcp() {
    let served = serve(1.0).await;
    let s = spec(&served, "chamber", "watlow-f4t-modbus", "tcp://");
    let mut c = WatlowChamber::new("chamber", connect(&s).await, Some(connector(s)), POLICY);
    chamber_round_trip(&mut c).await;
    let err = c.set_point(900.0).await.expect_err("beyond the chamber");
    assert!(err.to_string().contains("IllegalDataValue"), "{err}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn acl_driver_moves_and_turns_the_table_over_tcp_and_pty() {
    let served = serve(20.0).await;
    for (scheme, target) in [("tcp://", (0.0, 90.0)), ("pty://", (35.0, 180.0))] {
        let mut t = acl(&served, scheme).await;
        t.servo_on().await.expect("servo on");
        let target = TableAngles {
            outer_deg: target.0,
            inner_deg: target.1,
        };
        t.move_to(target).await.expect("move accepted");
        let mut ip = InPosition::new(0.01, 0.01, 1.0);
        let clock = served.bench.clock().clone();
        let mut settled = false;
        for _ in 0..400 {
            let r = t.read().await.expect("reading");
            if ip.update(&r, target, clock.now_s()) {
                settled = true;
                break;
            }
            tokio::time::sleep(Duration::from_millis(10)).await;
        }
        assert!(settled, "{scheme}: table never settled on {target:?}");
        // Rate mode in the instrument's own language: the inner axis
        // turns at 100 deg/s (far beyond the 20 deg/s of position moves),
        // a demand beyond the rate-mode limit is refused with the
        // instrument's error, and 0 brings the axis to rest.
        t.rate(true, 100.0).await.expect("turning accepted");
        let mut turning = false;
        for _ in 0..400 {
            let r = t.read().await.expect("reading");
            if (r.rates.inner_deg - 100.0).abs() < 1e-6 {
                turning = true;
                break;
            }
            tokio::time::sleep(Duration::from_millis(10)).await;
        }
        assert!(turning, "{scheme}: the inner axis never reached 100 deg/s");
        let err = t
            .rate(true, 600.0)
            .await
            .expect_err("beyond the rate-mode limit");
        assert!(err.to_string().contains("-222"), "{err}");
        t.rate(true, 0.0).await.expect("to rest");
        let mut rest = false;
        for _ in 0..400 {
            let r = t.read().await.expect("reading");
            if r.rates.inner_deg == 0.0 {
                rest = true;
                break;
            }
            tokio::time::sleep(Duration::from_millis(10)).await;
        }
        assert!(rest, "{scheme}: the inner axis never came to rest");
    }
}

async fn frames(served: &Served, scheme: &str, n: usize) -> GyroReader<BoxTransport> {
    let s = spec(served, "gyro", "rlg-frame", scheme);
    let mut g = GyroReader::new(
        "gyro",
        connect(&s).await,
        FrameLayout::default(),
        Duration::from_secs(2),
    );
    let mut last: Option<u8> = None;
    for _ in 0..n {
        let f = g.next_frame().await.expect("frame").expect("stream open");
        if let Some(l) = last {
            assert_eq!(f.seq, l.wrapping_add(1), "{scheme}: consecutive frames");
        }
        last = Some(f.seq);
        assert_eq!(f.status, 0x000F);
    }
    g
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn gyro_frames_arrive_complete_over_tcp_and_pty() {
    let served = serve(1.0).await;
    for scheme in ["tcp://", "pty://"] {
        let g = frames(&served, scheme, 400).await;
        let s = g.stats();
        assert_eq!((s.crc_errors, s.duplicates), (0, 0), "{scheme}: {s:?}");
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn transient_chamber_faults_are_retried_and_the_run_goes_on() {
    let served = serve(1.0).await;
    let f = &served.bench.faults.chamber;
    let mut c = espec(&served, "tcp://").await;
    f.no_reply.store(1, Ordering::Relaxed);
    c.read().await.expect("missed reply retried");
    f.garble.store(1, Ordering::Relaxed);
    c.read().await.expect("garbled reply retried");
    f.disconnect.store(true, Ordering::Relaxed);
    c.set_point(15.0).await.expect("reconnected");
    let k = c.link().counters();
    assert!(k.retries >= 3, "{k:?}");
    assert_eq!(k.reconnects, 1);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn persistent_faults_end_in_errors_that_name_the_device() {
    let served = serve(1.0).await;
    let mut c = espec(&served, "tcp://").await;
    served
        .bench
        .faults
        .chamber
        .silent
        .store(true, Ordering::Relaxed);
    let err = c.read().await.expect_err("silent chamber");
    assert!(
        matches!(err, DeviceError::Timeout { attempts: 3, .. }),
        "{err}"
    );
    assert!(
        err.to_string().starts_with("chamber: no reply to `TEMP?`"),
        "{err}"
    );
    served
        .bench
        .faults
        .chamber
        .silent
        .store(false, Ordering::Relaxed);

    served.bench.lock().raise_chamber_alarm(12);
    let r = c.read().await.expect("reading with alarm");
    assert_eq!(r.alarms, vec![12]);

    let mut t = acl(&served, "tcp://").await;
    served.bench.lock().trip_interlock();
    let err = t.stop().await.expect_err("tripped");
    assert!(matches!(err, DeviceError::Interlock { .. }), "{err}");
    t.servo_on().await.expect("reset and close");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn watlow_exception_and_missed_reply_are_retried() {
    let served = serve(1.0).await;
    let s = spec(&served, "chamber", "watlow-f4t-modbus", "tcp://");
    let mut c = WatlowChamber::new("chamber", connect(&s).await, Some(connector(s)), POLICY);
    served
        .bench
        .faults
        .chamber
        .error_reply
        .store(1, Ordering::Relaxed);
    c.read().await.expect("busy exception retried");
    served
        .bench
        .faults
        .chamber
        .no_reply
        .store(1, Ordering::Relaxed);
    c.read()
        .await
        .expect("missed reply retried after reconnect");
    assert!(c.counters().retries >= 2);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn gyro_link_trouble_is_counted_and_silence_is_an_error() {
    let served = serve(1.0).await;
    let s = spec(&served, "gyro", "rlg-frame", "tcp://");
    let mut g = GyroReader::new(
        "gyro",
        connect(&s).await,
        FrameLayout::default(),
        Duration::from_millis(500),
    );
    g.next_frame().await.expect("frame").expect("open");
    served
        .bench
        .faults
        .gyro
        .corrupt_every
        .store(997, Ordering::Relaxed);
    for _ in 0..800 {
        g.next_frame().await.expect("frame").expect("open");
    }
    let st = g.stats();
    assert!(st.crc_errors > 0 && st.lost_frames > 0, "{st:?}");
    served
        .bench
        .faults
        .gyro
        .corrupt_every
        .store(0, Ordering::Relaxed);
    served
        .bench
        .faults
        .gyro
        .silent
        .store(true, Ordering::Relaxed);
    // Drain what was already in flight, then the silence shows.
    let err = loop {
        match g.next_frame().await {
            Ok(Some(_)) => continue,
            Ok(None) => panic!("stream closed"),
            Err(e) => break e,
        }
    };
    assert!(matches!(err, DeviceError::Silent { .. }), "{err}");
    assert!(
        err.to_string()
            .starts_with("gyro: no valid frame for 0.5 s"),
        "{err}"
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_bench_file_opens_every_device_of_sim_serve() {
    use crate::bench::{BenchConfig, open_bench};
    use crate::config::Source;
    let served = serve(1.0).await;
    let addr = |device: &str, protocol: &str| spec(&served, device, protocol, "tcp://").to_string();
    let text = std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/fixtures/bench/sim-serve.toml"
    ))
    .expect("fixture")
    .replace("tcp://127.0.0.1:5001", &addr("chamber", "espec-ascii"))
    .replace("tcp://127.0.0.1:5003", &addr("table", "acl"))
    .replace("tcp://127.0.0.1:5004", &addr("gyro", "rlg-frame"))
    .replace("tcp://127.0.0.1:5025", &addr("supply", "keysight-e36300"));
    let cfg =
        BenchConfig::from_source(&Source::from_text("bench.toml", &text)).expect("valid bench");
    let mut b = open_bench(&cfg).await.expect("every device opens");
    assert_eq!(b.chamber.read().await.expect("chamber").air_c, 20.0);
    b.table.servo_on().await.expect("servo on");
    assert_eq!(b.table.read().await.expect("table").angles.outer_deg, 90.0);
    assert!(b.gyro.next_frame().await.expect("gyro").is_some());

    let mut dead = cfg.clone();
    dead.devices.chamber.spec = "tcp://127.0.0.1:1".into();
    let err = open_bench(&dead)
        .await
        .expect_err("nothing listens on port 1");
    assert!(
        err.to_string()
            .starts_with("chamber: cannot open tcp://127.0.0.1:1: "),
        "{err}"
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn drivers_work_over_an_in_memory_duplex_too() {
    use crate::sim::{SharedBench, SimBench, acl::serve_acl, espec::serve_espec};
    use crate::twin::TwinConfig;
    let clock: Arc<dyn crate::clock::Clock> = Arc::new(crate::clock::WallClock::scaled(20.0));
    let bench = SharedBench::new(
        SimBench::new(TwinConfig::default_rl16(), 3, FrameLayout::default()),
        clock,
    );
    let (a, b) = tokio::io::duplex(4096);
    tokio::spawn(serve_espec(b, bench.clone()));
    let mut c = EspecChamber::new(LineLink::new("chamber", Box::new(a), None, POLICY), None);
    chamber_round_trip(&mut c).await;
    let (a, b) = tokio::io::duplex(4096);
    tokio::spawn(serve_acl(b, bench.clone()));
    let mut t = AclTable::new(LineLink::new("table", Box::new(a), None, POLICY));
    t.move_to(TableAngles {
        outer_deg: 0.0,
        inner_deg: 0.0,
    })
    .await
    .expect("move");
    // Same bench behind both: the table's move shows in the twin.
    let mut moving = false;
    for _ in 0..200 {
        moving = bench.lock().twin.table_moving();
        if moving {
            break;
        }
        tokio::time::sleep(Duration::from_millis(10)).await;
    }
    assert!(moving, "the move never showed in the twin");
}

/// A network drop shorter than the reconnect window costs a pause, not the
/// run: the chamber link and the gyro link are reopened with backoff, and
/// the gyro's time without frames is measured. Past the window, the device
/// is declared unreachable, naming the window.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_network_drop_within_the_window_is_ridden_out_and_a_longer_one_named() {
    let served = serve(1.0).await;
    let f = &served.bench.faults;
    let mut c = espec(&served, "tcp://").await;
    c.read().await.expect("before the drop");
    f.chamber.outage.start(Duration::from_millis(800));
    let t0 = tokio::time::Instant::now();
    c.read().await.expect("read once the link is back");
    assert!(
        t0.elapsed() >= Duration::from_millis(700),
        "it waited out the drop"
    );
    let k = c.link().counters();
    assert!(k.reconnects >= 1, "{k:?}");

    let s = spec(&served, "gyro", "rlg-frame", "tcp://");
    let mut g = GyroReader::new(
        "gyro",
        connect(&s).await,
        FrameLayout::default(),
        Duration::from_secs(2),
    )
    .with_reconnect(connector(s), Duration::from_secs(3));
    for _ in 0..100 {
        g.next_frame().await.expect("frame").expect("open");
    }
    f.gyro.outage.start(Duration::from_millis(600));
    // Frames resume after the drop, and the drop shows in the figures.
    for _ in 0..1000 {
        g.next_frame()
            .await
            .expect("frames across the drop")
            .expect("open");
    }
    // Backoff: a few attempts over the drop (0.25 s, then 0.5 s later, ...),
    // never a spin.
    let st = g.stats();
    assert!((1..=3).contains(&st.reconnects), "{st:?}");
    assert!(st.longest_gap_ms >= 500, "{st:?}");
    assert!(st.lost_frames > 0, "{st:?}");

    f.chamber.outage.start(Duration::from_secs(6));
    let t0 = tokio::time::Instant::now();
    let err = c.read().await.expect_err("beyond the window");
    assert!(matches!(err, DeviceError::Unreachable { .. }), "{err}");
    assert!(
        err.to_string()
            .starts_with("chamber: the link dropped and could not be reopened within 3 s"),
        "{err}"
    );
    assert!(t0.elapsed() >= Duration::from_secs(3));
}

/// Drain a gyro line until `done` holds for a frame (the frames already
/// in flight first); the frame.
async fn frame_until(
    g: &mut GyroReader<BoxTransport>,
    done: impl Fn(&crate::protocol::frame::WireFrame) -> bool,
) -> crate::protocol::frame::WireFrame {
    for _ in 0..4_000 {
        let f = g.next_frame().await.expect("a frame").expect("open");
        if done(&f) {
            return f;
        }
    }
    panic!("no such frame in 4,000 (10 s of the gyro)");
}

/// The named faults of `run --inject`, played by the served simulators at
/// a device time and met by the real drivers as the embedded bench's
/// drivers meet them: alarm 9, the interlock, a stuck output, a unit that
/// draws three times its current until the protection trips. The
/// controller's own faults are refused by name, and so is `unit-lost` on
/// a bench of one unit.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_named_faults_play_on_the_wire_at_their_device_time() {
    use crate::sim::Fault;
    use crate::sim::serve::{can_play, schedule_faults};
    let served = serve(1.0).await;
    let mut c = espec(&served, "tcp://").await;
    let mut t = acl(&served, "tcp://").await;
    let s = spec(&served, "gyro", "rlg-frame", "tcp://");
    let mut g = GyroReader::new(
        "gyro",
        connect(&s).await,
        FrameLayout::default(),
        Duration::from_secs(1),
    );
    let mut p = supply(&served, Dialect::KeysightE36300, "tcp://").await;
    p.configure(2, 15.0, 1.0, true)
        .await
        .expect("settings taken");
    p.output(2, true).await.expect("output on");
    supply_until(&mut p, |r| r.on && r.a < 0.551 && r.a > 0.5).await;
    assert!(c.read().await.expect("reading").alarms.is_empty());
    assert_ne!(
        g.next_frame()
            .await
            .expect("frame")
            .expect("open")
            .delta_counts,
        crate::sim::faults::STUCK_COUNTS
    );

    let at = served.bench.clock().now_s() + 0.2;
    let (tx, mut rx) = tokio::sync::mpsc::unbounded_channel();
    let faults = [
        Fault::ChamberAlarm,
        Fault::TableInterlock,
        Fault::GyroStuck,
        Fault::SupplyOvercurrent,
    ];
    schedule_faults(
        &served.bench,
        faults.iter().map(|&f| (at, f)).collect(),
        move |when, f, r| {
            let _ = tx.send((when, f, r));
        },
    );
    for _ in faults {
        let (when, f, r) = rx.recv().await.expect("every fault played");
        assert!(r.is_ok() && when >= at, "{f:?} at {when} s: {r:?}");
    }
    assert_eq!(c.read().await.expect("reading").alarms, vec![9]);
    let err = t.stop().await.expect_err("tripped");
    assert!(matches!(err, DeviceError::Interlock { .. }), "{err}");
    frame_until(&mut g, |f| {
        f.delta_counts == crate::sim::faults::STUCK_COUNTS
    })
    .await;
    let tripped = supply_until(&mut p, |r| r.tripped).await;
    assert!(!tripped.on, "{tripped:?}");

    // Played again, a fault changes nothing; saturated stays saturated
    // when stuck is played after it, as on the embedded bench.
    let steady = served.bench.lock().supply.load.0.steady_a;
    for f in [
        Fault::ChamberAlarm,
        Fault::SupplyOvercurrent,
        Fault::GyroSaturated,
        Fault::GyroStuck,
    ] {
        served.bench.play(f).expect("played again");
    }
    assert_eq!(c.read().await.expect("reading").alarms, vec![9]);
    assert_eq!(served.bench.lock().supply.load.0.steady_a, steady);
    assert_eq!(
        served.bench.lock().forced_counts,
        Some(crate::sim::faults::SATURATED_COUNTS)
    );

    let one = Serve::load(None).expect("defaults");
    for f in [Fault::ProcessKill, Fault::DiskFull, Fault::Panic] {
        let e = can_play(&one, f).expect_err("the controller's own");
        assert!(e.to_string().contains("run --inject"), "{e}");
        assert!(served.bench.play(f).is_err());
    }
    assert!(can_play(&one, Fault::UnitLost).is_err());
    assert!(served.bench.play(Fault::UnitLost).is_err());
}

/// `unit-lost` on a served batch: the last unit's line goes silent for
/// good while the first goes on.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_served_batch_loses_its_last_unit_by_name() {
    use crate::sim::Fault;
    use crate::sim::serve::can_play;
    let quad = Serve::load(Some(std::path::Path::new(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/fixtures/sim/quad.toml"
    ))))
    .expect("the batch's fixture");
    can_play(&quad, Fault::UnitLost).expect("a batch can lose a unit");
    let batch = start(&quad).await.expect("simulated batch starts");
    let line = |name: &str| {
        batch
            .endpoints
            .iter()
            .find(|e| e.device == name && e.address.starts_with("tcp://"))
            .expect("its gyro line")
            .address
            .parse::<DeviceSpec>()
            .expect("valid spec")
    };
    let names: Vec<String> = quad
        .units
        .iter()
        .map(|u| format!("gyro/{}", u.name))
        .collect();
    let (first, last) = (line(&names[0]), line(&names[names.len() - 1]));
    let reader = |t| {
        GyroReader::new(
            "gyro",
            t,
            FrameLayout::default(),
            Duration::from_millis(500),
        )
    };
    let mut g0 = reader(connect(&first).await);
    let mut gn = reader(connect(&last).await);
    gn.next_frame().await.expect("frame").expect("open");
    batch.bench.play(Fault::UnitLost).expect("played");
    let err = loop {
        match gn.next_frame().await {
            Ok(Some(_)) => continue,
            Ok(None) => panic!("stream closed"),
            Err(e) => break e,
        }
    };
    assert!(matches!(err, DeviceError::Silent { .. }), "{err}");
    g0.next_frame()
        .await
        .expect("the first unit goes on")
        .expect("open");
}
