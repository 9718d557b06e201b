//! `QUERY_STATE_DATA` is answered as the device document's command table says:
//! `ID_CMD_QUERY_STATE_DATA` (0x0E) from `ID_DEVICE_SUB_01..04` to `ID_DEVICE_MAIN`, one frame per
//! finger, not with the stream's position frames (`ID_CMD_QUERY_CONTROL_DATA`, 0x0F).
#![allow(clippy::unwrap_used)]

use std::time::Duration;

use teleop_allegro_protocol::{doc, Generation};
use teleop_can_link::CanFrame;
use teleop_sim_allegro::firmware::{Firmware, FirmwareOptions};
use teleop_sim_allegro::hand::{Hand, HandParams};

fn firmware(options: FirmwareOptions) -> Firmware {
    Firmware::new(options, Hand::allegro(HandParams::default(), None).unwrap())
}

fn query(fw: &mut Firmware, at: Duration) -> Vec<CanFrame> {
    let q: CanFrame = doc::Request::QueryState.encode(Generation::V3.torque_order());
    let mut out = Vec::new();
    fw.receive(at, &q, &mut out);
    out.into_iter().map(|(_, f)| f).collect()
}

fn id(f: &CanFrame) -> u16 {
    assert!(!f.is_extended());
    f.raw_id() as u16
}

#[test]
fn query_state_is_answered_with_0x0e_from_each_finger() {
    for g in [Generation::V1, Generation::V2, Generation::V3] {
        let mut fw = firmware(FirmwareOptions::new(g));
        let out = query(&mut fw, Duration::from_millis(5));
        let ids: Vec<u16> = out.iter().map(id).collect();
        // cmd 0x0E << 6 | ID_DEVICE_MAIN (2) << 3 | ID_DEVICE_SUB_01..04 (3..6).
        assert_eq!(ids, [0x393, 0x394, 0x395, 0x396], "{g}");
        for f in &out {
            let (cmd, dest, src) = doc::split(id(f));
            assert_eq!((cmd, dest), (0x0E, doc::ID_DEVICE_MAIN));
            assert!((doc::ID_DEVICE_SUB_01..=doc::ID_DEVICE_SUB_04).contains(&src));
        }
    }
}

/// The answer's payload is not documented: as a position frame (the finger's four raw counts,
/// the same as its 0x0F frame of that instant), or none.
#[test]
fn the_state_answers_payload_is_an_option() {
    use teleop_sim_allegro::firmware::StateAnswer;
    let mut o = FirmwareOptions::new(Generation::V3);
    o.state_answer = StateAnswer::Positions;
    let mut fw = firmware(o.clone());
    fw.hand_mut().set_position(5, 0.3);
    let out = query(&mut fw, Duration::from_millis(5));
    match doc::Report::decode(&out[1]).unwrap() {
        doc::Report::State { finger, len, data } => {
            assert_eq!((finger, len), (1, 8));
            let raw = u16::from_le_bytes([data[2], data[3]]);
            assert!((o.calibration[5].doc_raw_to_rad(raw) - 0.3).abs() < 1e-3);
        }
        other => panic!("{other:?}"),
    }
    o.state_answer = StateAnswer::Empty;
    let mut fw = firmware(o);
    let out = query(&mut fw, Duration::from_millis(5));
    assert_eq!(out.len(), 4);
    for (f, frame) in out.iter().enumerate() {
        assert_eq!(
            doc::Report::decode(frame).unwrap(),
            doc::Report::State {
                finger: f as u8,
                len: 0,
                data: [0; 8]
            }
        );
    }
}
