//! What each cycle's command asks of the motors, as the shipped driver schedules it
//! (docs/devices/shadow.md, "One 1 kHz cycle": E `sr06.cpp`, `sr_robot_lib`; C's
//! `motor_data_polling.yaml`, the same for every hand):
//!
//! - `which_motors` flips every cycle; the requested type advances when it flips to 1, so each
//!   type is asked of the odd motors, then of the even ones: (t0, 0) (t1, 1) (t1, 0) (t2, 1) ...
//! - types go round-robin SGL, SGR, PWM, FLAGS, CURRENT; timers take single turns: voltage every
//!   2 s, temperature every 1 s, CAN rx/tx counts and error counters every 0.1 s;
//! - at start, until every motor has answered every slow type or 5 s have passed: SLOW_MISC and
//!   the P, I, D terms instead;
//! - the demand words: torque or PWM demands by configuration, 0 for a motor whose demand is
//!   stopped (a serious flag).

use teleop_shadow_protocol::data::{EdcCommand, EdcNumbering, FromMotor, ToMotor};
use teleop_shadow_protocol::layout::{Command, MOTORS};

/// The round-robin of normal operation.
pub const ROUND_ROBIN: [FromMotor; 5] = [
    FromMotor::StrainGaugeLeft,
    FromMotor::StrainGaugeRight,
    FromMotor::Pwm,
    FromMotor::Flags,
    FromMotor::Current,
];

/// The round-robin at start.
pub const AT_START: [FromMotor; 4] = [
    FromMotor::SlowMisc,
    FromMotor::PTerm,
    FromMotor::ITerm,
    FromMotor::DTerm,
];

/// The longest the start round-robin runs, ms.
pub const START_MS: u64 = 5000;

/// How the motors are driven.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum DemandMode {
    /// PWM demands (the shipped default, `PWM_CONTROL`).
    #[default]
    Pwm,
    /// Torque demands.
    Torque,
}

/// A timed request: its type and period.
#[derive(Debug, Clone, Copy)]
struct Timer {
    kinds: &'static [FromMotor],
    period_ms: u64,
    next_ms: u64,
}

/// The request schedule.
#[derive(Debug, Clone)]
pub struct Schedule {
    numbering: EdcNumbering,
    mode: DemandMode,
    start_ms: u64,
    which: i16,
    kind: FromMotor,
    round: usize,
    timers: [Timer; 3],
    queued: Vec<FromMotor>,
}

impl Schedule {
    /// A schedule starting at `now_ms`.
    pub fn new(numbering: EdcNumbering, mode: DemandMode, now_ms: u64) -> Self {
        const CAN: [FromMotor; 3] = [
            FromMotor::CanRx,
            FromMotor::CanTx,
            FromMotor::CanErrorCounters,
        ];
        let timer = |kinds: &'static [FromMotor], period_ms| Timer {
            kinds,
            period_ms,
            next_ms: now_ms + period_ms,
        };
        Self {
            numbering,
            mode,
            start_ms: now_ms,
            which: 1,
            kind: AT_START[0],
            round: 0,
            timers: [
                timer(&[FromMotor::Voltage], 2000),
                timer(&[FromMotor::Temperature], 1000),
                timer(&CAN, 100),
            ],
            queued: Vec::with_capacity(8),
        }
    }

    /// The command of the cycle at `now_ms`: the motors' demands (`demands[n]`, 0 for a motor
    /// whose demand is stopped), and whether every motor has answered the start requests.
    pub fn next(&mut self, now_ms: u64, demands: &[i16; MOTORS], started: bool) -> Command {
        self.which ^= 1;
        if self.which == 1 {
            self.kind = self.advance(now_ms, started);
        }
        let edc = EdcCommand::SensorData.value(self.numbering).unwrap_or(1);
        Command {
            edc_command: edc,
            from_motor_data_type: self.kind as u32,
            which_motors: self.which,
            to_motor_data_type: match self.mode {
                DemandMode::Pwm => ToMotor::PwmDemand as u32,
                DemandMode::Torque => ToMotor::TorqueDemand as u32,
            },
            motor_data: *demands,
            tactile_data_type: teleop_shadow_protocol::data::tactile::PST3,
        }
    }

    fn advance(&mut self, now_ms: u64, started: bool) -> FromMotor {
        let starting = !started && now_ms.saturating_sub(self.start_ms) < START_MS;
        if starting {
            self.round = (self.round + 1) % AT_START.len();
            return AT_START[self.round];
        }
        for t in &mut self.timers {
            if now_ms >= t.next_ms {
                // Late timers do not pile up: the next turn is one period from now.
                t.next_ms = now_ms + t.period_ms;
                self.queued.extend_from_slice(t.kinds);
            }
        }
        if !self.queued.is_empty() {
            return self.queued.remove(0);
        }
        self.round = (self.round + 1) % ROUND_ROBIN.len();
        ROUND_ROBIN[self.round]
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use super::*;

    fn kinds(s: &mut Schedule, from_ms: u64, cycles: u64, started: bool) -> Vec<(u32, i16)> {
        (0..cycles)
            .map(|k| {
                let c = s.next(from_ms + k, &[0; MOTORS], started);
                (c.from_motor_data_type, c.which_motors)
            })
            .collect()
    }

    #[test]
    fn each_type_goes_to_the_odd_then_the_even_motors() {
        let mut s = Schedule::new(EdcNumbering::Shipped, DemandMode::Pwm, 0);
        let seen = kinds(&mut s, 0, 11, true);
        // The first cycle asks the even motors; from then on pairs (odd, even) of one type.
        assert_eq!(seen[0].1, 0);
        let t = |k: FromMotor| k as u32;
        let pairs: Vec<u32> = seen[1..]
            .chunks(2)
            .map(|p| {
                assert_eq!((p[0].1, p[1].1), (1, 0));
                assert_eq!(p[0].0, p[1].0);
                p[0].0
            })
            .collect();
        assert_eq!(
            pairs,
            vec![
                t(FromMotor::StrainGaugeRight),
                t(FromMotor::Pwm),
                t(FromMotor::Flags),
                t(FromMotor::Current),
                t(FromMotor::StrainGaugeLeft),
            ]
        );
    }

    #[test]
    fn start_requests_until_started_or_five_seconds() {
        let mut s = Schedule::new(EdcNumbering::Shipped, DemandMode::Pwm, 0);
        let early = kinds(&mut s, 0, 200, false);
        assert!(early
            .iter()
            .all(|(k, _)| AT_START.iter().any(|a| *a as u32 == *k)));
        // After 5 s (from the next pair of cycles on: a type is asked of both halves).
        let late = kinds(&mut s, 5000, 20, false);
        assert!(late[1..]
            .iter()
            .all(|(k, _)| !AT_START.iter().any(|a| *a as u32 == *k)));
    }

    #[test]
    fn timers_take_single_turns_at_their_rates() {
        let mut s = Schedule::new(EdcNumbering::Shipped, DemandMode::Torque, 0);
        let seen = kinds(&mut s, 0, 10_000, true);
        let count = |k: FromMotor| {
            seen.iter()
                .filter(|(x, w)| *x == k as u32 && *w == 1)
                .count()
        };
        // 10 s: temperature about 10 times, voltage about 5, each CAN type about 100.
        assert!((9..=10).contains(&count(FromMotor::Temperature)));
        assert!((4..=5).contains(&count(FromMotor::Voltage)));
        assert!((95..=100).contains(&count(FromMotor::CanRx)));
        // The round-robin gets the rest.
        assert!(count(FromMotor::Flags) > 800);
        let c = s.next(10_000, &[7; MOTORS], true);
        assert_eq!(c.to_motor_data_type, ToMotor::TorqueDemand as u32);
        assert_eq!(c.motor_data, [7; MOTORS]);
        assert_eq!(c.edc_command, 1);
    }
}
