//! From the palm's sensor words to the 24 joint angles of `hand/state` (docs/devices/shadow.md,
//! "Sensors"): each joint's ADC channel (THJ5 and WRJ1: the mean of their A and B sensors),
//! calibrated per joint by a piecewise-linear table of (raw, rad) points, as Shadow's per-hand
//! calibration files give them. A finger's J1 and J2 are calibrated separately; the motor that
//! drives them both sees J0 = J1 + J2 ([`teleop_shadow_protocol::mapping::Dof`]).

use teleop_shadow_protocol::layout::SENSORS;
use teleop_shadow_protocol::mapping::HAND_CHANNELS;
pub use teleop_shadow_protocol::mapping::HAND_JOINTS as JOINTS;

use crate::config::ShadowConfig;

/// Linear interpolation in a calibration table (extrapolating from the end segments).
pub fn calibrate(table: &[[f64; 2]], raw: f64) -> f64 {
    let Some(first) = table.first() else {
        return 0.0;
    };
    if table.len() < 2 {
        return first[1];
    }
    let i = table
        .windows(2)
        .position(|w| raw < w[1][0])
        .unwrap_or(table.len() - 2);
    let (a, b) = (table[i], table[i + 1]);
    a[1] + (raw - a[0]) * (b[1] - a[1]) / (b[0] - a[0])
}

/// The calibration tables of the 24 joints, resolved from the configuration once.
#[derive(Debug, Clone)]
pub struct Calibration {
    tables: Vec<Vec<[f64; 2]>>,
}

impl Calibration {
    /// The tables of `config`.
    pub fn new(config: &ShadowConfig) -> Self {
        Self {
            tables: JOINTS.iter().map(|j| config.table(j).clone()).collect(),
        }
    }

    /// The 24 joint angles (rad) of a status's sensor words.
    pub fn angles(&self, sensors: &[u16; SENSORS]) -> [f64; 24] {
        std::array::from_fn(|j| {
            let (a, b) = HAND_CHANNELS[j];
            let raw = match b {
                Some(b) => (f64::from(sensors[a]) + f64::from(sensors[b])) / 2.0,
                None => f64::from(sensors[a]),
            };
            calibrate(&self.tables[j], raw)
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tables_interpolate_and_extrapolate() {
        let t = [[1000.0, 0.0], [2000.0, 1.0], [3000.0, 1.5]];
        assert_eq!(calibrate(&t, 1500.0), 0.5);
        assert_eq!(calibrate(&t, 2500.0), 1.25);
        assert_eq!(calibrate(&t, 500.0), -0.5);
        assert_eq!(calibrate(&t, 4000.0), 2.0);
    }

    #[test]
    fn thj5_reads_the_mean_of_its_two_sensors() {
        let cal = Calibration::new(&ShadowConfig::default());
        let mut s = [2048u16; SENSORS];
        s[21] = 2048 + 1200;
        s[22] = 2048 + 600;
        let a = cal.angles(&s);
        assert!((a[21] - 0.75).abs() < 1e-9);
        assert!(a[0].abs() < 1e-9);
    }
}
