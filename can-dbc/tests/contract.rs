//! The generated codecs against the contract in DESIGN.md, property tests for every
//! encode/decode pair, and the E2E protection.

// Helpers outside #[test] functions unwrap and panic as the tests do.
#![allow(clippy::expect_used)]

use golf_car_can::e2e::{self, E2eError, E2eRx, E2eTx, crc8_sae_j1850, frame_crc, protect};
use golf_car_can::spec::{ByteOrder, SignalSpec, ValueLabel};
use golf_car_can::*;
use proptest::prelude::*;
use std::borrow::Cow;

/// A row of DESIGN.md's CAN table: ID, message, period and receiver timeout (ms),
/// receivers.
type DesignRow = (
    u16,
    &'static str,
    Option<u32>,
    Option<u32>,
    &'static [&'static str],
);

#[test]
fn network_matches_the_design_table() {
    let expect: [DesignRow; 6] = [
        (
            0x080,
            "CONTROLLER_HEARTBEAT",
            Some(20),
            Some(100),
            &["CONTROLLER"],
        ),
        (0x100, "STEERING_CMD", Some(10), Some(100), &["CONTROLLER"]),
        (0x101, "STEERING_REPORT", Some(10), None, &["STEERING_ECU"]),
        (0x110, "THROTTLE_CMD", Some(10), Some(100), &["CONTROLLER"]),
        (0x111, "THROTTLE_REPORT", Some(10), None, &["THROTTLE_ECU"]),
        (
            0x0F0,
            "FAULT_REPORT",
            Some(100),
            None,
            &["CONTROLLER", "STEERING_ECU", "THROTTLE_ECU"],
        ),
    ];
    assert_eq!(NETWORK.messages.len(), expect.len());
    assert_eq!(NETWORK.baudrate, 500_000);
    for (id, name, cycle, timeout, senders) in expect {
        let m = NETWORK
            .message(id)
            .unwrap_or_else(|| panic!("{id:#x} missing"));
        assert_eq!(m.name, name);
        assert_eq!(m.cycle_time_ms, cycle, "{name} cycle");
        assert_eq!(m.timeout_ms, timeout, "{name} timeout");
        let got: Vec<&str> = m.senders.iter().map(|s| s.as_ref()).collect();
        assert_eq!(got, senders, "{name} senders");
        let counter = m.signal("Counter").expect("counter");
        assert_eq!((counter.start_bit, counter.size), (48, 4));
        let crc = m.signal("Crc").expect("crc");
        assert_eq!((crc.start_bit, crc.size), (56, 8));
    }
}

#[test]
fn generated_tables_equal_the_dbc_parsed_at_run_time() {
    let parsed = NetworkSpec::from_dbc(GOLF_CAR_DBC).expect("golf_car.dbc parses");
    assert_eq!(parsed, NETWORK);
}

#[test]
fn crc8_sae_j1850_check_value() {
    // The catalogue check value of CRC-8/SAE-J1850 over "123456789".
    assert_eq!(crc8_sae_j1850(b"123456789"), 0x4B);
    assert_eq!(crc8_sae_j1850(&[]), 0x00);
}

#[test]
fn the_table_driven_crc_equals_the_bitwise_definition() {
    // poly 0x1D, init 0xFF, xor-out 0xFF, a bit at a time.
    let bitwise = |bytes: &[u8]| {
        let mut crc: u8 = 0xFF;
        for &b in bytes {
            crc ^= b;
            for _ in 0..8 {
                crc = if crc & 0x80 != 0 {
                    (crc << 1) ^ 0x1D
                } else {
                    crc << 1
                };
            }
        }
        crc ^ 0xFF
    };
    for b in 0..=255u8 {
        assert_eq!(crc8_sae_j1850(&[b]), bitwise(&[b]), "{b:#04x}");
    }
    // Frames' worth of pseudo-random bytes (a 32-bit LCG).
    let mut x: u32 = 12345;
    let mut byte = || {
        x = x.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
        (x >> 24) as u8
    };
    for len in 0..=12 {
        for _ in 0..200 {
            let bytes: Vec<u8> = (0..len).map(|_| byte()).collect();
            assert_eq!(crc8_sae_j1850(&bytes), bitwise(&bytes), "{bytes:?}");
        }
    }
}

#[test]
fn crc_covers_id_big_endian_then_bytes_0_to_6() {
    let data = [1, 2, 3, 4, 5, 6, 7, 0xAA];
    let by_hand = crc8_sae_j1850(&[0x01, 0x00, 1, 2, 3, 4, 5, 6, 7]);
    assert_eq!(frame_crc(0x100, &data), by_hand);
    assert_ne!(frame_crc(0x101, &data), by_hand, "the ID is covered");
}

#[test]
fn physical_values_round_to_the_nearest_step() {
    // 12.349 deg is 1234.9 raw: rounding gives 1235, truncation would give 1234.
    let cmd = SteeringCmd {
        enable: true,
        target_angle: 12.349,
        max_rate: 0.0,
    };
    let back = SteeringCmd::decode(&cmd.encode().unwrap()).unwrap();
    assert!(
        (back.target_angle - 12.35).abs() < 1e-9,
        "{}",
        back.target_angle
    );
    let neg = SteeringCmd {
        target_angle: -0.006,
        ..cmd
    };
    let back = SteeringCmd::decode(&neg.encode().unwrap()).unwrap();
    assert!(
        (back.target_angle + 0.01).abs() < 1e-9,
        "{}",
        back.target_angle
    );
}

#[test]
fn out_of_range_values_are_refused_with_the_signal_named() {
    let cmd = SteeringCmd {
        enable: true,
        target_angle: 50.0,
        max_rate: 10.0,
    };
    match cmd.encode() {
        Err(CodecError::OutOfRange { signal, .. }) => assert_eq!(signal, "TargetAngle"),
        other => panic!("expected OutOfRange, got {other:?}"),
    }
    let nan = ThrottleCmd {
        target_speed: f64::NAN,
        ..Default::default()
    };
    assert!(matches!(nan.encode(), Err(CodecError::OutOfRange { .. })));
}

#[test]
fn undefined_enum_values_and_short_payloads_are_refused() {
    let mut data = ThrottleCmd::default().encode().unwrap();
    data[0] |= 0b1100; // Gear = 3, not in the value table
    assert!(matches!(
        ThrottleCmd::decode(&data),
        Err(CodecError::UndefinedValue {
            signal: "Gear",
            raw: 3,
            ..
        })
    ));
    assert!(matches!(
        SteeringReport::decode(&[0; 7]),
        Err(CodecError::WrongLength { len: 7, .. })
    ));
    assert!(matches!(
        GolfCarMessage::decode(0x7FF, &[0; 8]),
        Err(CodecError::UnknownId(0x7FF))
    ));
}

#[test]
fn e2e_rejects_bad_crc_repeat_skip_dlc_and_unknown_id() {
    let mut tx = E2eTx::new();
    let mut rx = E2eRx::new(&NETWORK);
    let hb = ControllerHeartbeat {
        state: ControllerHeartbeatState::Auto,
    };
    let f0 = tx.seal_message(&hb).unwrap();
    let f1 = tx.seal_message(&hb).unwrap();
    let f2 = tx.seal_message(&hb).unwrap();
    let f3 = tx.seal_message(&hb).unwrap();
    assert!(rx.accept_parts(0x80, false, false, &f0).is_ok());
    assert_eq!(
        rx.accept_parts(0x80, false, false, &f0),
        Err(E2eError::RepeatedCounter {
            id: 0x80,
            counter: 0
        })
    );
    let mut corrupt = f1;
    corrupt[0] ^= 0x01;
    assert!(matches!(
        rx.accept_parts(0x80, false, false, &corrupt),
        Err(E2eError::BadCrc { id: 0x80, .. })
    ));
    assert!(rx.accept_parts(0x80, false, false, &f1).is_ok());
    assert_eq!(
        rx.accept_parts(0x80, false, false, &f3),
        Err(E2eError::SkippedCounter {
            id: 0x80,
            last: 1,
            expected: 2,
            found: 3
        })
    );
    // Re-synchronised on the skipped frame: its successor passes, f2 is now stale.
    let f4 = tx.seal_message(&hb).unwrap();
    assert!(rx.accept_parts(0x80, false, false, &f4).is_ok());
    assert!(rx.accept_parts(0x80, false, false, &f2).is_err());
    assert_eq!(
        rx.accept_parts(0x80, false, false, &f4[..7]),
        Err(E2eError::WrongDlc { id: 0x80, dlc: 7 })
    );
    assert_eq!(
        rx.accept_parts(0x123, false, false, &f4),
        Err(E2eError::UnknownId {
            id: 0x123,
            extended: false
        })
    );
    assert_eq!(
        rx.accept_parts(0x80, true, false, &f4),
        Err(E2eError::UnknownId {
            id: 0x80,
            extended: true
        })
    );
    assert_eq!(
        rx.accept_parts(0x80, false, true, &[]),
        Err(E2eError::RemoteFrame { id: 0x80 })
    );
    let s = rx.stats();
    assert_eq!(
        (s.accepted, s.repeated_counter, s.bad_crc, s.skipped_counter),
        (3, 1, 1, 2)
    );
    assert_eq!((s.wrong_dlc, s.unknown_id, s.remote), (1, 2, 1));
    assert_eq!(s.rejected(), 8);
}

#[test]
fn counters_are_per_id_and_wrap_after_15() {
    let mut tx = E2eTx::new();
    let mut rx = E2eRx::new(&NETWORK);
    for i in 0..40u32 {
        let steer = tx.seal_message(&SteeringCmd::default()).unwrap();
        assert_eq!(e2e::counter_of(&steer), (i % 16) as u8);
        assert!(rx.accept_parts(0x100, false, false, &steer).is_ok());
        if i % 3 == 0 {
            let thr = tx.seal_message(&ThrottleCmd::default()).unwrap();
            assert!(rx.accept_parts(0x110, false, false, &thr).is_ok());
        }
    }
    assert_eq!(rx.stats().rejected(), 0);
}

fn any_steering_cmd() -> impl Strategy<Value = SteeringCmd> {
    (any::<bool>(), -45.0..=45.0f64, 0.0..=500.0f64).prop_map(|(enable, target_angle, max_rate)| {
        SteeringCmd {
            enable,
            target_angle,
            max_rate,
        }
    })
}

fn any_steering_report() -> impl Strategy<Value = SteeringReport> {
    (
        any::<bool>(),
        any::<bool>(),
        prop::sample::select(SteeringReportFault::ALL.to_vec()),
        -45.0..=45.0f64,
        -500.0..=500.0f64,
        0.0..=25.5f64,
    )
        .prop_map(
            |(enabled, r#override, fault, angle, rate, motor_current)| SteeringReport {
                enabled,
                r#override,
                fault,
                angle,
                rate,
                motor_current,
            },
        )
}

fn any_throttle_cmd() -> impl Strategy<Value = ThrottleCmd> {
    (
        any::<bool>(),
        prop::sample::select(ThrottleCmdGear::ALL.to_vec()),
        0.0..=100.0f64,
        0.0..=10.0f64,
        0.0..=5.0f64,
    )
        .prop_map(
            |(enable, gear, brake, target_speed, accel_limit)| ThrottleCmd {
                enable,
                gear,
                brake,
                target_speed,
                accel_limit,
            },
        )
}

fn any_throttle_report() -> impl Strategy<Value = ThrottleReport> {
    (
        any::<bool>(),
        prop::sample::select(ThrottleReportGear::ALL.to_vec()),
        prop::sample::select(ThrottleReportFault::ALL.to_vec()),
        -10.0..=10.0f64,
        0.0..=100.0f64,
        0.0..=100.0f64,
    )
        .prop_map(
            |(enabled, gear, fault, wheel_speed, throttle, brake)| ThrottleReport {
                enabled,
                gear,
                fault,
                wheel_speed,
                throttle,
                brake,
            },
        )
}

fn any_fault_report() -> impl Strategy<Value = FaultReport> {
    (
        prop::sample::select(FaultReportSource::ALL.to_vec()),
        prop::sample::select(FaultReportCode::ALL.to_vec()),
        any::<u16>(),
    )
        .prop_map(|(source, code, detail)| FaultReport {
            source,
            code,
            detail,
        })
}

fn any_heartbeat() -> impl Strategy<Value = ControllerHeartbeat> {
    prop::sample::select(ControllerHeartbeatState::ALL.to_vec())
        .prop_map(|state| ControllerHeartbeat { state })
}

/// Every physical field within half a resolution step.
fn close(a: f64, b: f64, factor: f64) -> bool {
    (a - b).abs() <= factor / 2.0 + 1e-9
}

fn roundtrip<M: CanMessage + std::fmt::Debug>(m: &M) -> M {
    let mut tx = E2eTx::new();
    let data = tx.seal_message(m).expect("in-range values encode");
    let mut rx = E2eRx::new(&NETWORK);
    let (id, payload) = rx
        .accept_parts(u32::from(M::ID), false, false, &data)
        .expect("E2E ok");
    assert_eq!(id, M::ID);
    M::decode(&payload).expect("decodes")
}

proptest! {
    #[test]
    fn steering_cmd_roundtrip(m in any_steering_cmd()) {
        let b = roundtrip(&m);
        prop_assert_eq!(b.enable, m.enable);
        prop_assert!(close(b.target_angle, m.target_angle, 0.01));
        prop_assert!(close(b.max_rate, m.max_rate, 0.1));
    }

    #[test]
    fn steering_report_roundtrip(m in any_steering_report()) {
        let b = roundtrip(&m);
        prop_assert_eq!((b.enabled, b.r#override, b.fault), (m.enabled, m.r#override, m.fault));
        prop_assert!(close(b.angle, m.angle, 0.01));
        prop_assert!(close(b.rate, m.rate, 0.1));
        prop_assert!(close(b.motor_current, m.motor_current, 0.1));
    }

    #[test]
    fn throttle_cmd_roundtrip(m in any_throttle_cmd()) {
        let b = roundtrip(&m);
        prop_assert_eq!((b.enable, b.gear), (m.enable, m.gear));
        prop_assert!(close(b.brake, m.brake, 0.5));
        prop_assert!(close(b.target_speed, m.target_speed, 0.01));
        prop_assert!(close(b.accel_limit, m.accel_limit, 0.02));
    }

    #[test]
    fn throttle_report_roundtrip(m in any_throttle_report()) {
        let b = roundtrip(&m);
        prop_assert_eq!((b.enabled, b.gear, b.fault), (m.enabled, m.gear, m.fault));
        prop_assert!(close(b.wheel_speed, m.wheel_speed, 0.01));
        prop_assert!(close(b.throttle, m.throttle, 0.5));
        prop_assert!(close(b.brake, m.brake, 0.5));
    }

    #[test]
    fn fault_report_roundtrip(m in any_fault_report()) {
        prop_assert_eq!(roundtrip(&m), m);
    }

    #[test]
    fn heartbeat_roundtrip(m in any_heartbeat()) {
        prop_assert_eq!(roundtrip(&m), m);
    }

    /// Encoding a decoded payload gives the same bytes (the E2E bytes aside).
    #[test]
    fn decode_then_encode_is_identity_on_valid_payloads(m in any_throttle_report()) {
        let data = m.encode().unwrap();
        let again = ThrottleReport::decode(&data).unwrap().encode().unwrap();
        prop_assert_eq!(data, again);
    }

    /// CRC-8 detects every single-bit error in the protected bytes.
    #[test]
    fn any_single_bit_flip_is_rejected(m in any_steering_cmd(), bit in 0usize..64) {
        let mut tx = E2eTx::new();
        let mut data = tx.seal_message(&m).unwrap();
        data[bit / 8] ^= 1 << (bit % 8);
        let mut rx = E2eRx::new(&NETWORK);
        let result = rx.accept_parts(0x100, false, false, &data);
        prop_assert!(matches!(result, Err(E2eError::BadCrc { .. })), "{:?}", result);
    }

    /// A flipped ID bit is caught too (the ID is inside the CRC).
    #[test]
    fn frame_moved_to_another_id_is_rejected(m in any_steering_cmd()) {
        let mut data = m.encode().unwrap();
        protect(0x100, &mut data, 5);
        let mut rx = E2eRx::new(&NETWORK);
        let result = rx.accept_parts(0x101, false, false, &data);
        prop_assert!(matches!(result, Err(E2eError::BadCrc { .. })), "{:?}", result);
    }

    /// Only the successor of the last counter is accepted.
    #[test]
    fn only_the_next_counter_passes(last in 0u8..16, next in 0u8..16) {
        let mut data = [0u8; 8];
        protect(0x111, &mut data, next);
        let result = e2e::check(&NETWORK, 0x111, false, false, &data, Some(last));
        prop_assert_eq!(result.is_ok(), next == (last + 1) % 16);
    }

    /// Generic packing: any raw value of any signal layout, Intel or Motorola,
    /// signed or not, survives set/get and leaves the other bits alone.
    #[test]
    fn raw_pack_unpack(start in 0u16..64, size in 1u8..=64, motorola in any::<bool>(),
                       signed in any::<bool>(), seed in any::<u64>(), noise in any::<[u8; 8]>()) {
        let s = SignalSpec {
            name: Cow::Borrowed("S"), start_bit: start, size,
            byte_order: if motorola { ByteOrder::Motorola } else { ByteOrder::Intel },
            signed, factor: 1.0, offset: 0.0, min: 0.0, max: 0.0, unit: Cow::Borrowed(""),
            receivers: Cow::Borrowed(&[]), values: Cow::Borrowed(&[] as &[ValueLabel]),
            comment: Cow::Borrowed(""),
        };
        let bits = s.bit_positions();
        prop_assume!(bits.iter().all(|b| *b < 64));
        let (lo, hi) = s.raw_bounds();
        let raw = lo + (i128::from(seed) % (hi - lo + 1));
        let mut data = noise;
        s.set_raw(&mut data, raw).unwrap();
        prop_assert_eq!(s.get_raw(&data), raw);
        for bit in 0..64 {
            if !bits.contains(&bit) {
                prop_assert_eq!(data[bit / 8] >> (bit % 8) & 1, noise[bit / 8] >> (bit % 8) & 1);
            }
        }
    }
}

#[test]
fn motorola_layout_matches_the_dbc_sawtooth() {
    // A 16-bit big-endian signal with start bit 7 is bytes 0 (MSB) and 1 (LSB).
    let s = SignalSpec {
        name: Cow::Borrowed("S"),
        start_bit: 7,
        size: 16,
        byte_order: ByteOrder::Motorola,
        signed: false,
        factor: 1.0,
        offset: 0.0,
        min: 0.0,
        max: 65535.0,
        unit: Cow::Borrowed(""),
        receivers: Cow::Borrowed(&[]),
        values: Cow::Borrowed(&[]),
        comment: Cow::Borrowed(""),
    };
    let mut data = [0u8; 8];
    s.set_raw(&mut data, 0x1234).unwrap();
    assert_eq!(&data[..2], &[0x12, 0x34]);
}

#[test]
fn malformed_dbc_is_refused_with_a_clear_error() {
    let syntax = NetworkSpec::from_dbc("VERSION \"x\"\nBO_ 256 BROKEN 8 X\n").unwrap_err();
    let text = syntax.to_string();
    assert!(text.contains("syntax") && text.contains("2:"), "{text}");

    let overlap = GOLF_CAR_DBC.replace("SG_ MaxRate : 32|16@1+", "SG_ MaxRate : 30|16@1+");
    let err = NetworkSpec::from_dbc(&overlap).unwrap_err().to_string();
    assert!(
        err.contains("STEERING_CMD") && err.contains("overlap"),
        "{err}"
    );

    let no_crc = GOLF_CAR_DBC.replacen(
        " SG_ Crc : 56|8@1+ (1,0) [0|255] \"\" STEERING_ECU,THROTTLE_ECU\n",
        "",
        1,
    );
    let err = NetworkSpec::from_dbc(&no_crc).unwrap_err().to_string();
    assert!(
        err.contains("CONTROLLER_HEARTBEAT") && err.contains("Crc"),
        "{err}"
    );

    let short = GOLF_CAR_DBC.replace("BO_ 257 STEERING_REPORT: 8", "BO_ 257 STEERING_REPORT: 6");
    let err = NetworkSpec::from_dbc(&short).unwrap_err().to_string();
    assert!(
        err.contains("STEERING_REPORT") && err.contains("DLC 6"),
        "{err}"
    );

    let dup = GOLF_CAR_DBC.replace("BO_ 273 THROTTLE_REPORT", "BO_ 272 THROTTLE_REPORT");
    let err = NetworkSpec::from_dbc(&dup).unwrap_err().to_string();
    assert!(err.contains("defined twice"), "{err}");

    // Found by the dbc_spec fuzz target (fuzz/regressions/dbc_spec): a standard ID
    // beyond 11 bits was taken, and a frame of it could never be sent.
    let wide = GOLF_CAR_DBC.replace("BO_ 256 STEERING_CMD", "BO_ 7128 STEERING_CMD");
    let err = NetworkSpec::from_dbc(&wide).unwrap_err().to_string();
    assert!(
        err.contains("STEERING_CMD") && err.contains("0x1bd8") && err.contains("11 bits"),
        "{err}"
    );
    let widest = GOLF_CAR_DBC.replace("BO_ 256 STEERING_CMD", "BO_ 2048 STEERING_CMD");
    assert!(NetworkSpec::from_dbc(&widest).is_err());
}

#[test]
fn fault_reports_from_several_senders_keep_separate_counters() {
    let mut steering_tx = E2eTx::new();
    let mut throttle_tx = E2eTx::new();
    let mut rx = E2eRx::new(&NETWORK);
    let report = |source| FaultReport {
        source,
        code: FaultReportCode::CommandTimeout,
        detail: 0x100,
    };
    for _ in 0..20 {
        let a = steering_tx
            .seal_message(&report(FaultReportSource::SteeringEcu))
            .unwrap();
        let b = throttle_tx
            .seal_message(&report(FaultReportSource::ThrottleEcu))
            .unwrap();
        assert!(rx.accept_parts(0xF0, false, false, &a).is_ok());
        assert!(rx.accept_parts(0xF0, false, false, &b).is_ok());
    }
    // A replay within one sender's stream is still caught.
    let again = {
        let mut tx = E2eTx::new();
        tx.seal_message(&report(FaultReportSource::SteeringEcu))
            .unwrap()
    };
    assert!(rx.accept_parts(0xF0, false, false, &again).is_err());
    assert_eq!(rx.stats().accepted, 40);
}

#[test]
fn a_nodes_ids_are_what_it_sends_and_receives() {
    let ids = |node: &str| {
        let mut v = NETWORK.ids_of_node(node);
        v.sort_unstable();
        v
    };
    // The controller sends the heartbeat, both commands and fault reports, and reads
    // both reports.
    assert_eq!(ids("CONTROLLER"), [128, 240, 256, 257, 272, 273]);
    // The steering ECU: the heartbeat and its command in, its report and fault reports
    // out; nothing of the throttle's.
    assert_eq!(ids("STEERING_ECU"), [128, 240, 256, 257]);
    assert!(ids("NOBODY").is_empty());
}
