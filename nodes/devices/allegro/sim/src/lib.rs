//! The simulated Wonik Allegro Hand, for running the Allegro pipeline without hardware.
//!
//! It speaks the real wire protocols (the `teleop-allegro-protocol` codecs) on a simulated CAN
//! bus at 1 Mbit/s, but implements the hand's behaviour on its own:
//!
//! - [`hand`]: 16 joints driven by motor torque, with inertia, damping, joint limits, optional
//!   gravity, a virtual object the fingers close on and motor temperatures (pure);
//! - [`firmware`]: the hand's firmware on the bus for each protocol generation (v1-v3: the
//!   device document's protocol with the version's torque joint order and PWM scale; v4):
//!   period, SYSTEM_ON/OFF, streaming on its own clock, queries, torque frames (pure);
//! - [`adapter`]: a USB slcan adapter (CANable or Lawicel acks) as a state machine (pure);
//! - [`serve`]: the bus, the adapter on the simulator kit's pseudo-terminal behind a stable
//!   link, the socket bus, and faults injected at run time;
//! - [`control`]: the control socket's commands (the kit's vocabulary and the hand's own).
//!
//! Must not depend on: the Allegro node (a driver bug must not hide behind shared driver code).

pub mod adapter;
pub mod control;
pub mod firmware;
pub mod hand;
pub mod serve;

pub use serve::{BusStats, Faults, Sim, SimOptions, BUS_BITRATE};

use teleop_can_link::CanFrame;

/// A frame written candump style: `3D3#0080008000800080` (hex id, `#`, hex data), `200#R` (a
/// remote frame, optionally `200#R8` with its DLC); ids above 0x7FF or of 8 digits are
/// extended.
pub fn parse_frame(text: &str) -> Result<CanFrame, String> {
    let (id, data) = text
        .split_once('#')
        .ok_or_else(|| format!("{text:?}: expected ID#DATA or ID#R"))?;
    let raw = u32::from_str_radix(id, 16).map_err(|_| format!("{text:?}: bad id {id:?}"))?;
    let extended = id.len() > 3 || raw > 0x7FF;
    if let Some(dlc) = data.strip_prefix('R') {
        let dlc = if dlc.is_empty() {
            0
        } else {
            dlc.parse::<u8>()
                .map_err(|_| format!("{text:?}: bad remote DLC {dlc:?}"))?
        };
        let frame = if extended {
            CanFrame::extended_remote(raw, dlc)
        } else {
            u16::try_from(raw)
                .ok()
                .and_then(|id| CanFrame::standard_remote(id, dlc))
        };
        return frame.ok_or_else(|| format!("{text:?}: id or DLC out of range"));
    }
    if data.len() % 2 != 0 {
        return Err(format!("{text:?}: odd number of hex digits"));
    }
    let bytes = (0..data.len())
        .step_by(2)
        .map(|i| {
            data.get(i..i + 2)
                .and_then(|b| u8::from_str_radix(b, 16).ok())
                .ok_or_else(|| format!("{text:?}: bad data {data:?}"))
        })
        .collect::<Result<Vec<u8>, String>>()?;
    let frame = if extended {
        CanFrame::extended(raw, &bytes)
    } else {
        u16::try_from(raw)
            .ok()
            .and_then(|id| CanFrame::standard(id, &bytes))
    };
    frame.ok_or_else(|| format!("{text:?}: id out of range or more than 8 data bytes"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn candump_frames_parse() {
        assert_eq!(
            parse_frame("3D3#0080008000800080"),
            Ok(CanFrame::standard(0x3D3, &[0, 0x80, 0, 0x80, 0, 0x80, 0, 0x80]).expect("frame"))
        );
        assert_eq!(
            parse_frame("200#R"),
            Ok(CanFrame::standard_remote(0x200, 0).expect("frame"))
        );
        assert_eq!(
            parse_frame("12345678#01"),
            Ok(CanFrame::extended(0x1234_5678, &[1]).expect("frame"))
        );
        assert_eq!(
            parse_frame("7FF#"),
            Ok(CanFrame::standard(0x7FF, &[]).expect("frame"))
        );
        for bad in [
            "",
            "3D3",
            "xyz#00",
            "3D3#0",
            "3D3#zz",
            "3D3#000000000000000000",
            "200#Rx",
        ] {
            assert!(parse_frame(bad).is_err(), "{bad}");
        }
    }
}
