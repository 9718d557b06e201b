//! The Shadow Hand as a `teleop-ecat-master` driver: two SubDevices (the bridge, then the palm)
//! identified by product code; the palm's sync managers and FMMUs programmed in PRE-OP as the
//! shipped driver does (its SII announces none); one LRW of the command and bridge command out
//! and the status and bridge status back each cycle; position control on the host toward the
//! retargeted targets, every cycle (torque or PWM demands with per-joint gains and limits);
//! motor flags and silent motors reported by name.

use std::time::Instant;

use ethercrab::{Command as EcatCommand, MainDevice};
use teleop_ecat_master::{Driver, Found, Image, OwnLayout, PreOpGroup};
use teleop_msgs::HandCommand;
use teleop_shadow_protocol::data::{flags, tactile, EdcNumbering};
use teleop_shadow_protocol::layout::{
    CanBridge, Command, Protocol, Status, MOTORS, PRODUCT_BRIDGE, TACTILE,
};
use teleop_shadow_protocol::mapping::Dof;

use crate::config::{Checked, Gains, ShadowConfig};
use crate::joints::Calibration;
use crate::motors::Motors;
use crate::schedule::Schedule;

/// First logical address of the process data (the shipped driver's).
pub const LOGICAL_START: u32 = 0x0001_0000;
/// The palm's position on the bus (after the bridge).
pub const PALM: usize = 1;
/// Working counter of a cycle whose command was taken (LRW write: 2) and whose status the palm
/// had refilled (read: 1).
pub const EXPECTED_WKC: u16 = 3;
/// Speed estimate filter: the weight of the newest sample.
const SPEED_FILTER: f64 = 0.2;

/// The palm that bring-up found.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct PalmInfo {
    /// Vendor ID (not public for Shadow: logged).
    pub vendor_id: u32,
    /// Product code (6: SR06).
    pub product_code: u32,
    /// Revision.
    pub revision: u32,
    /// Serial (names the hand on a real system).
    pub serial: u32,
}

/// What one status says, for the host.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Inputs {
    /// Joint angles, rad ([`JOINTS`] order).
    pub angles: [f64; 24],
    /// Joint speeds, rad/s (filtered differences).
    pub speeds: [f64; 24],
    /// Joint efforts from the strain gauges, N m (a coupled J1/J2 pair shares its motor's).
    pub efforts: [f64; 24],
    /// Each joint's motor flags (a finger's J1 and J2: its J0 motor's).
    pub flags: [u16; 24],
    /// Motor currents, mA, per joint (as `efforts`).
    pub currents_ma: [f64; 24],
    /// PST pressure and temperature per fingertip (FF, MF, RF, LF, TH) when the palm sent PST
    /// data.
    pub pst: Option<[(u16, u16); TACTILE]>,
    /// Bit n: motor n's demand is stopped by a serious flag.
    pub stopped: u32,
    /// Bit n: motor n has not answered for `motor_timeout_ms`.
    pub silent: u32,
}

/// The Shadow driver.
#[derive(Debug)]
pub struct Shadow {
    config: ShadowConfig,
    checked: Checked,
    calibration: Calibration,
    dofs: [Option<Dof>; MOTORS],
    gains: [Gains; MOTORS],
    schedule: Schedule,
    motors: Motors,
    palm: PalmInfo,
    palm_address: u16,
    clock: Instant,
    start_ms: u64,
    /// The last commanded joint targets (rad); what the hand holds when it has no command.
    target: Option<[f64; 24]>,
    last: Option<(u64, [f64; 24])>,
    speeds: [f64; 24],
    reported_stopped: u32,
    reported_silent: u32,
}

impl Shadow {
    /// A driver for a hand configured by `config` (checked: `checked`).
    pub fn new(config: ShadowConfig, checked: Checked) -> Self {
        let dofs = checked.mapping.dofs();
        let gains =
            std::array::from_fn(|m| dofs[m].map_or(config.gains, |d: Dof| config.gains_of(d.name)));
        Self {
            calibration: Calibration::new(&config),
            schedule: Schedule::new(checked.numbering, checked.demand, 0),
            dofs,
            gains,
            motors: Motors::default(),
            palm: PalmInfo::default(),
            palm_address: 0,
            clock: Instant::now(),
            start_ms: 0,
            target: None,
            last: None,
            speeds: [0.0; 24],
            reported_stopped: 0,
            reported_silent: 0,
            config,
            checked,
        }
    }

    /// The node configuration.
    pub fn config(&self) -> &ShadowConfig {
        &self.config
    }

    /// The palm found at the latest bring-up.
    pub fn palm(&self) -> PalmInfo {
        self.palm
    }

    /// The motors as the statuses describe them.
    pub fn motors(&self) -> &Motors {
        &self.motors
    }

    /// What each motor drives.
    pub fn dofs(&self) -> [Option<Dof>; MOTORS] {
        self.dofs
    }

    /// The EDC command numbering of the palm's firmware.
    pub fn numbering(&self) -> EdcNumbering {
        self.checked.numbering
    }

    fn now_ms(&self) -> u64 {
        self.clock.elapsed().as_millis() as u64
    }

    /// The demands toward the target (none: 0), gated by the motors' serious flags.
    fn demands(&self) -> [i16; MOTORS] {
        let Some(target) = &self.target else {
            return [0; MOTORS];
        };
        let Some((_, angles)) = &self.last else {
            return [0; MOTORS];
        };
        let demands = std::array::from_fn(|m| {
            let Some(d) = self.dofs[m] else { return 0 };
            let g = self.gains[m];
            let u = g.kp * (d.of(target) - d.of(angles)) - g.kd * d.of(&self.speeds);
            u.clamp(-g.max_effort, g.max_effort).round() as i16
        });
        self.motors.gate(&demands)
    }

    /// Writes this cycle's command (and an idle bridge message) into the palm's outputs.
    fn write(&mut self, outputs: &mut Image) {
        let demands = self.demands();
        let now = self.now_ms();
        let command: Command = self.schedule.next(now, &demands, self.motors.started());
        let out = outputs.subdevice_mut(PALM);
        if out.len() >= Command::SIZE + CanBridge::SIZE {
            out[..Command::SIZE].copy_from_slice(&command.pack());
            out[Command::SIZE..Command::SIZE + CanBridge::SIZE]
                .copy_from_slice(&CanBridge::default().pack());
        }
    }

    fn report(&mut self, now: u64) {
        let stopped = (0..MOTORS)
            .filter(|m| self.motors.motors[*m].stopped())
            .fold(0u32, |b, m| b | 1 << m);
        for m in 0..MOTORS {
            let bit = 1u32 << m;
            let joint = self.dofs[m].map_or("?", |d| d.name);
            if stopped & bit != 0 && self.reported_stopped & bit == 0 {
                let f = self.motors.motors[m].flags;
                tracing::warn!(
                    motor = m,
                    joint,
                    flags = format!("{f:#06x}"),
                    "motor {m} ({joint}) stopped by {}: its demand is 0",
                    flags::names(f & flags::SERIOUS).join(", ")
                );
            } else if stopped & bit == 0 && self.reported_stopped & bit != 0 {
                tracing::info!(motor = m, joint, "motor {m} ({joint}) runs again");
            }
        }
        self.reported_stopped = stopped;
        let silent = self
            .motors
            .silent(now, self.start_ms, self.config.motor_timeout_ms);
        for m in 0..MOTORS {
            let bit = 1u32 << m;
            let joint = self.dofs[m].map_or("?", |d| d.name);
            if silent & bit != 0 && self.reported_silent & bit == 0 {
                tracing::warn!(motor = m, joint, "motor {m} ({joint}) stopped answering");
            } else if silent & bit == 0 && self.reported_silent & bit != 0 {
                tracing::info!(motor = m, joint, "motor {m} ({joint}) answers again");
            }
        }
        self.reported_silent = silent;
    }
}

/// The FMMU register block: logical start, length, bits 0..7, physical start, type, enable.
fn fmmu(logical: u32, len: u16, physical: u16, write: bool) -> [u8; 16] {
    let mut b = [0u8; 16];
    b[..4].copy_from_slice(&logical.to_le_bytes());
    b[4..6].copy_from_slice(&len.to_le_bytes());
    b[7] = 7;
    b[8..10].copy_from_slice(&physical.to_le_bytes());
    b[11] = if write { 2 } else { 1 };
    b[12] = 1;
    b
}

/// The sync manager register block: start, length, control, status, enable, PDI control.
fn sm(start: u16, len: u16, control: u8) -> [u8; 8] {
    let mut b = [0u8; 8];
    b[..2].copy_from_slice(&start.to_le_bytes());
    b[2..4].copy_from_slice(&len.to_le_bytes());
    b[4] = control;
    b[6] = 1;
    b
}

impl Driver for Shadow {
    type Command = HandCommand;
    type Inputs = Inputs;
    type Polled = ();

    fn name(&self) -> &str {
        "Shadow Hand"
    }

    fn identify(&self, found: &[Found]) -> anyhow::Result<()> {
        let names: Vec<String> = found
            .iter()
            .map(|f| {
                format!(
                    "{} (vendor {:#x}, product {:#x})",
                    f.name, f.identity.vendor_id, f.identity.product_id
                )
            })
            .collect();
        let [bridge, palm] = found else {
            anyhow::bail!(
                "expected a Shadow Hand (two SubDevices: the bridge, product 0, then the palm, \
                 product 6); found {}: {}",
                found.len(),
                names.join(", ")
            );
        };
        if bridge.identity.product_id != PRODUCT_BRIDGE {
            anyhow::bail!(
                "SubDevice 0 is not a Shadow bridge (product 0): {}",
                names[0]
            );
        }
        match Protocol::from_product_code(palm.identity.product_id) {
            Some(Protocol::P0220) => Ok(()),
            Some(other) => anyhow::bail!(
                "SubDevice 1 is a Shadow palm of protocol {other:?} ({}); this node speaks 0220 \
                 (SR06, Hand E) only",
                names[1]
            ),
            None => anyhow::bail!("SubDevice 1 is not a Shadow palm (product 6): {}", names[1]),
        }
    }

    async fn configure(
        &mut self,
        md: &MainDevice<'static>,
        group: &PreOpGroup,
    ) -> anyhow::Result<()> {
        let palm = group
            .iter(md)
            .nth(PALM)
            .ok_or_else(|| anyhow::anyhow!("the palm left the bus during bring-up"))?;
        let id = palm.identity();
        self.palm = PalmInfo {
            vendor_id: id.vendor_id,
            product_code: id.product_id,
            revision: id.revision,
            serial: id.serial,
        };
        self.palm_address = palm.configured_address();
        // The vendor ID is not public: log what this hand says.
        tracing::info!(
            vendor_id = format!("{:#010x}", id.vendor_id),
            serial = id.serial,
            revision = id.revision,
            "Shadow palm found (protocol 0220)"
        );
        let a = Protocol::P0220.area();
        let bridge = CanBridge::SIZE as u16;
        let out_len = a.command_len + bridge;
        let in_len = a.status_len + bridge;
        let addr = self.palm_address;
        // Sync managers: one buffer each; AL event on the two the master writes.
        for (n, block) in [
            sm(a.command, a.command_len, 0x26),
            sm(a.bridge_command, bridge, 0x26),
            sm(a.status, a.status_len, 0x02),
            sm(a.bridge_status, bridge, 0x02),
        ]
        .iter()
        .enumerate()
        {
            EcatCommand::fpwr(addr, 0x0800 + 8 * n as u16)
                .send(md, block)
                .await
                .map_err(|e| anyhow::anyhow!("programming the palm's SM{n}: {e}"))?;
        }
        for (n, block) in [
            fmmu(LOGICAL_START, out_len, a.command, true),
            fmmu(LOGICAL_START + u32::from(out_len), in_len, a.status, false),
        ]
        .iter()
        .enumerate()
        {
            EcatCommand::fpwr(addr, 0x0600 + 16 * n as u16)
                .send(md, block)
                .await
                .map_err(|e| anyhow::anyhow!("programming the palm's FMMU{n}: {e}"))?;
        }
        // A fresh start for the schedule and the motors' view.
        self.clock = Instant::now();
        self.start_ms = 0;
        self.schedule = Schedule::new(self.checked.numbering, self.checked.demand, 0);
        self.motors = Motors::default();
        self.last = None;
        self.speeds = [0.0; 24];
        Ok(())
    }

    fn own_layout(&self) -> Option<OwnLayout> {
        let a = Protocol::P0220.area();
        let bridge = CanBridge::SIZE;
        Some(OwnLayout {
            logical_start: LOGICAL_START,
            parts: vec![
                (0, 0),
                (
                    usize::from(a.command_len) + bridge,
                    usize::from(a.status_len) + bridge,
                ),
            ],
            expected_wkc: EXPECTED_WKC,
        })
    }

    /// Takes the admitted command's targets (radians within the hand profile's limits, in its
    /// joint order): the host's position control drives toward them from this cycle on.
    fn pack(&mut self, command: &HandCommand, outputs: &mut Image) -> bool {
        let mut target = [0.0; 24];
        for (t, j) in target.iter_mut().zip(&command.joints) {
            *t = f64::from(j.target);
        }
        self.target = Some(target);
        self.write(outputs);
        true
    }

    fn unpack(&mut self, inputs: &Image, _: Option<&()>) -> Option<Inputs> {
        let part = inputs.subdevice(PALM);
        let status = Status::unpack(part.get(..Status::SIZE)?).ok()?;
        if status.edc_command != 1 {
            return None; // booting, or nothing valid
        }
        let now = self.now_ms();
        self.motors.update(&status, now);
        self.report(now);
        let angles = self.calibration.angles(&status.sensors);
        if let Some((t, prev)) = &self.last {
            let dt = now.saturating_sub(*t) as f64 / 1000.0;
            if dt > 0.0 {
                for j in 0..24 {
                    let v = (angles[j] - prev[j]) / dt;
                    self.speeds[j] += SPEED_FILTER * (v - self.speeds[j]);
                }
            }
        }
        if self.last.is_none_or(|(t, _)| t != now) {
            self.last = Some((now, angles));
        }
        let mut efforts = [0.0; 24];
        let mut currents = [0.0; 24];
        let mut joint_flags = [0u16; 24];
        for (m, d) in self.dofs.iter().enumerate() {
            let Some(d) = d else { continue };
            let motor = &self.motors.motors[m];
            for j in [Some(d.joints.0), d.joints.1].into_iter().flatten() {
                efforts[j] = f64::from(motor.torque) * self.config.effort_nm_per_unit;
                currents[j] = motor.current_ma;
                joint_flags[j] = motor.flags;
            }
        }
        let pst = (status.tactile_data_type == tactile::PST3).then(|| {
            std::array::from_fn(|f| {
                if status.tactile_data_valid & (1 << f) != 0 {
                    (status.tactile[f][0], status.tactile[f][1])
                } else {
                    (0, 0)
                }
            })
        });
        Some(Inputs {
            angles,
            speeds: self.speeds,
            efforts,
            flags: joint_flags,
            currents_ma: currents,
            pst,
            stopped: self.reported_stopped,
            silent: self.reported_silent,
        })
    }

    fn hold(&mut self, last: Option<&Inputs>, outputs: &mut Image) {
        if self.target.is_none() {
            // Nothing commanded yet: hold where the hand is (no demand before the first status).
            self.target = last.map(|i| i.angles);
        }
        self.write(outputs);
    }

    fn hold_every_cycle(&self) -> bool {
        true
    }
}
