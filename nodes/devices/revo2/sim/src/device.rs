//! The Revo2's firmware as an EtherCAT application: its object dictionary (from
//! `teleop-revo2-protocol`), PDO assignment, process data, configuration side effects, the
//! simulated hand behind them, and the firmware upgrade over FoE in BOOT ([`crate::firmware`]:
//! after a successful one the device restarts with the new version). Plugs into the generic
//! `teleop-ecat-sim` SubDevice.

use std::collections::BTreeMap;
use std::time::Duration;

use teleop_ecat_sim::{AlState, AppRequest, Application, MailboxContext, MailboxReply, SdoAbort};
use teleop_revo2_protocol::{
    entry, mapping_entries, obj, Access, Board, DefaultValue, Inputs, JointData, Outputs,
    TactileData, UnitMode, Version, DEFAULT_JOINT_RANGES, DEFAULT_RX_ASSIGNMENT,
    DEFAULT_TX_ASSIGNMENT, DICTIONARY, FOE_AUTH_CODE, FOE_FILE_TYPE, MODE_NONE,
};

use crate::firmware::{FlashTiming, Upgrade};
use crate::hand::{Hand, FINGERTIPS, JOINTS};

/// FoE mailbox type.
const MAILBOX_FOE: u8 = 0x04;

/// Firmware versions and serial numbers the emulated device reports.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Versions {
    /// 0x8000:11 control board firmware.
    pub control_fw: String,
    /// 0x8000:12 control board serial number.
    pub control_sn: String,
    /// 0x8000:13 wrist board firmware.
    pub wrist_fw: String,
    /// 0x8000:14 wrist board serial number.
    pub wrist_sn: String,
    /// 0x8010:0D..11 fingertip sensor firmware.
    pub tactile_fw: String,
}

impl Default for Versions {
    fn default() -> Self {
        Self {
            control_fw: "1.4.2".into(),
            control_sn: "RV2C24110000042".into(),
            wrist_fw: "0.9.7".into(),
            wrist_sn: "RV2W24110000042".into(),
            tactile_fw: "1.0.3".into(),
        }
    }
}

/// The emulated Revo2 application.
pub struct Revo2 {
    hand: Hand,
    values: BTreeMap<(u16, u8), Vec<u8>>,
    rx_assign: Vec<u16>,
    tx_assign: Vec<u16>,
    last_outputs: Outputs,
    /// Process-data cycles with outputs applied (for tests and the control socket).
    pub output_cycles: u64,
    /// Times the SM watchdog made the hand hold.
    pub holds: u64,
    upgrade: Upgrade,
    /// Restarts after a firmware upgrade.
    pub restarts: u64,
    /// PDO mappings presented instead of the documented ones (see [`Revo2::present_mapping`]).
    mappings: BTreeMap<u16, Vec<u32>>,
    /// Objects whose reads are aborted (see [`Revo2::fail_reads`]).
    failing_reads: Vec<(u16, u8)>,
}

impl Revo2 {
    /// A Revo2 with its factory configuration and this hand.
    pub fn new(hand: Hand, versions: &Versions) -> Self {
        let mut values = BTreeMap::new();
        for e in DICTIONARY {
            if is_live(e.index) || e.sub == 0 {
                continue;
            }
            let bytes = match e.default {
                Some(DefaultValue::Unsigned(v)) => v.to_le_bytes()[..e.byte_len().min(4)].to_vec(),
                Some(DefaultValue::Str(s)) => s.as_bytes().to_vec(),
                None if e.data_type.is_string() => Vec::new(),
                None => vec![0; e.byte_len()],
            };
            values.insert((e.index, e.sub), bytes);
        }
        for (sub, text) in [
            (0x11, &versions.control_fw),
            (0x12, &versions.control_sn),
            (0x13, &versions.wrist_fw),
            (0x14, &versions.wrist_sn),
        ] {
            values.insert((obj::CONFIG, sub), text.as_bytes().to_vec());
        }
        // Capacitive tactile sensors with their own firmware.
        values.insert((obj::TACTILE_CONFIG, 0x06), vec![1]);
        for sub in 0x0D..=0x11 {
            values.insert(
                (obj::TACTILE_CONFIG, sub),
                versions.tactile_fw.as_bytes().to_vec(),
            );
        }
        Self {
            hand,
            values,
            rx_assign: DEFAULT_RX_ASSIGNMENT.to_vec(),
            tx_assign: DEFAULT_TX_ASSIGNMENT.to_vec(),
            last_outputs: Outputs::default(),
            output_cycles: 0,
            holds: 0,
            upgrade: Upgrade::new(FlashTiming::default()),
            restarts: 0,
            mappings: BTreeMap::new(),
            failing_reads: Vec::new(),
        }
    }

    /// The boot loader (flash content, timing, faults).
    pub fn upgrade(&self) -> &Upgrade {
        &self.upgrade
    }

    /// The boot loader, to set its timing or inject faults.
    pub fn upgrade_mut(&mut self) -> &mut Upgrade {
        &mut self.upgrade
    }

    /// The firmware versions now reported: (control board 0x8000:11, wrist board 0x8000:13).
    pub fn firmware_versions(&self) -> (String, String) {
        let text = |sub| {
            String::from_utf8_lossy(self.value(obj::CONFIG, sub).unwrap_or_default()).into_owned()
        };
        (text(0x11), text(0x13))
    }

    /// The restart after an upgrade: the new version is reported, the upgrade settings are
    /// gone and the PDO assignment is back to its power-on default (the device boots).
    fn restart_with(&mut self, board: Board, (major, minor, patch): Version) {
        let sub = match board {
            Board::Control => 0x11,
            Board::Wrist => 0x13,
        };
        self.values.insert(
            (obj::CONFIG, sub),
            format!("{major}.{minor}.{patch}").into_bytes(),
        );
        self.values.insert(FOE_FILE_TYPE, vec![0]);
        self.values.insert(FOE_AUTH_CODE, Vec::new());
        self.rx_assign = DEFAULT_RX_ASSIGNMENT.to_vec();
        self.tx_assign = DEFAULT_TX_ASSIGNMENT.to_vec();
        self.last_outputs = Outputs::default();
        self.hand.hold();
        self.restarts += 1;
    }

    /// The hand.
    pub fn hand(&self) -> &Hand {
        &self.hand
    }

    /// The hand, to place objects.
    pub fn hand_mut(&mut self) -> &mut Hand {
        &mut self.hand
    }

    /// The current input (TxPDO) assignment.
    pub fn tx_assignment(&self) -> &[u16] {
        &self.tx_assign
    }

    /// Makes the board serial numbers (0x8000:12, 0x8000:14) read as on a device whose were
    /// never written: 16 bytes of 0xFF (erased flash), not text.
    pub fn erase_serial_numbers(&mut self) {
        for sub in [0x12, 0x14] {
            self.values.insert((obj::CONFIG, sub), vec![0xFF; 16]);
        }
    }

    /// Presents `entries` (encoded mapping entries) as the mapping of PDO `pdo` (0x1600, 0x1A00,
    /// 0x1A01) when it is read, as a device with other firmware would; the process data stays
    /// the documented layout.
    pub fn present_mapping(&mut self, pdo: u16, entries: Vec<u32>) {
        self.mappings.insert(pdo, entries);
    }

    /// Aborts every read of `index:sub` (a broken object).
    pub fn fail_reads(&mut self, index: u16, sub: u8) {
        self.failing_reads.push((index, sub));
    }

    /// A configuration value as stored (raw bytes).
    pub fn value(&self, index: u16, sub: u8) -> Option<&[u8]> {
        self.values.get(&(index, sub)).map(Vec::as_slice)
    }

    fn unit_mode(&self) -> UnitMode {
        match self
            .values
            .get(&(obj::CONFIG, 0x05))
            .and_then(|v| v.first())
        {
            Some(1) => UnitMode::Physical,
            _ => UnitMode::Percent,
        }
    }

    /// Converts a command parameter to the hand's percentage units.
    fn to_percent(&self, joint: usize, mode: u8, param: f32, first: bool) -> f32 {
        let is_position = first && matches!(mode, 1 | 2);
        match (self.unit_mode(), is_position) {
            (UnitMode::Physical, true) => {
                let r = DEFAULT_JOINT_RANGES[joint];
                f32::from(r.degrees_to_percent(param))
            }
            (UnitMode::Physical, false) if first && mode == 4 => param, // mA = per mille of 1000 mA
            (UnitMode::Physical, false) if !first && mode == 2 => {
                let r = DEFAULT_JOINT_RANGES[joint];
                // deg/s -> per mille of the maximum speed (full travel in 0.5 s).
                param / ((r.max_deg - r.min_deg).max(1.0) * 2.0) * 1000.0
            }
            _ => param,
        }
    }

    fn apply(&mut self, outputs: &Outputs) {
        let multi = outputs.multi;
        if multi.mode != MODE_NONE {
            for j in 0..JOINTS {
                let p1 = self.to_percent(j, multi.mode, f32::from(multi.param1[j]), true);
                let p2 = self.to_percent(j, multi.mode, f32::from(multi.param2[j]), false);
                self.hand.command(j, multi.mode, p1, p2);
            }
        }
        let single = outputs.single;
        if single.mode != MODE_NONE {
            let j = usize::from(single.joint);
            if j < JOINTS {
                let p1 = self.to_percent(j, single.mode, f32::from(single.param1), true);
                let p2 = self.to_percent(j, single.mode, f32::from(single.param2), false);
                self.hand.command(j, single.mode, p1, p2);
            }
        }
    }

    fn inputs(&self) -> Inputs {
        let physical = self.unit_mode() == UnitMode::Physical;
        let pos = self.hand.positions();
        let speed = self.hand.speeds();
        let current = self.hand.currents();
        let joints = JointData {
            position: core::array::from_fn(|j| {
                let p = pos[j].round().clamp(0.0, 1000.0) as u16;
                if physical {
                    DEFAULT_JOINT_RANGES[j].percent_to_degrees(p).round() as u16
                } else {
                    p
                }
            }),
            speed: core::array::from_fn(|j| {
                let per_mille = speed[j] / 2000.0 * 1000.0;
                let v = if physical {
                    let r = DEFAULT_JOINT_RANGES[j];
                    speed[j] / 1000.0 * (r.max_deg - r.min_deg)
                } else {
                    per_mille
                };
                v.round().clamp(-32768.0, 32767.0) as i16
            }),
            current: current.map(|c| c.round().clamp(-32768.0, 32767.0) as i16),
            status: [0; JOINTS],
        };
        let touches = self.hand.touches();
        let counter = u16::from(self.hand.sensor_counter()) << 8;
        let raw = |n: f32| (n * 100.0).round().clamp(0.0, 2500.0) as u16;
        let tactile = TactileData {
            normal: core::array::from_fn(|i| raw(touches[i].normal_n)),
            tangential: core::array::from_fn(|i| raw(touches[i].tangential_n)),
            direction: core::array::from_fn(|i| touches[i].direction_deg.unwrap_or(0xFFFF)),
            proximity: core::array::from_fn(|i| touches[i].proximity),
            touch_status: [counter; FINGERTIPS],
        };
        Inputs {
            joints,
            tactile: Some(tactile),
        }
    }

    fn assignment(&mut self, index: u16) -> &mut Vec<u16> {
        if index == obj::SM2_ASSIGN {
            &mut self.rx_assign
        } else {
            &mut self.tx_assign
        }
    }
}

/// Objects whose values come from the hand or the process data, not from storage.
fn is_live(index: u16) -> bool {
    matches!(
        index,
        obj::JOINT_INPUTS | obj::TACTILE_INPUTS | obj::MULTI_FINGER | obj::SINGLE_FINGER
    ) || mapping_entries(index).is_some()
        || index == obj::SM2_ASSIGN
        || index == obj::SM3_ASSIGN
}

fn list<T: Copy>(values: &[T], sub: u8, bytes: impl Fn(T) -> Vec<u8>) -> Result<Vec<u8>, SdoAbort> {
    match sub {
        0 => Ok(vec![values.len() as u8]),
        n => values
            .get(usize::from(n) - 1)
            .map(|&v| bytes(v))
            .ok_or(SdoAbort::SUBINDEX_DOES_NOT_EXIST),
    }
}

impl Application for Revo2 {
    fn sdo_read(&mut self, index: u16, sub: u8) -> Result<Vec<u8>, SdoAbort> {
        if index == obj::SM2_ASSIGN || index == obj::SM3_ASSIGN {
            let values = self.assignment(index).clone();
            return list(&values, sub, |v| v.to_le_bytes().to_vec());
        }
        if self.failing_reads.contains(&(index, sub)) {
            return Err(SdoAbort::GENERAL);
        }
        if let Some(presented) = self.mappings.get(&index) {
            return list(presented, sub, |m| m.to_le_bytes().to_vec());
        }
        if let Some(mapping) = mapping_entries(index) {
            return list(mapping, sub, |m| m.encode().to_le_bytes().to_vec());
        }
        // SOEM reads the sync manager types.
        if index == 0x1C00 {
            return list(&[1u8, 2, 3, 4], sub, |v| vec![v]);
        }
        let Some(e) = entry(index, sub) else {
            return Err(
                if entry(index, 0).is_some() || DICTIONARY.iter().any(|e| e.index == index) {
                    SdoAbort::SUBINDEX_DOES_NOT_EXIST
                } else {
                    SdoAbort::OBJECT_DOES_NOT_EXIST
                },
            );
        };
        if e.access == Access::Wo {
            return Err(SdoAbort::WRITE_ONLY);
        }
        if sub == 0 {
            let n = DICTIONARY
                .iter()
                .filter(|x| x.index == index && x.sub != 0)
                .map(|x| x.sub)
                .max();
            return Ok(vec![n.unwrap_or(0)]);
        }
        let mut image = [0u8; 128];
        match index {
            obj::JOINT_INPUTS | obj::TACTILE_INPUTS => {
                let inputs = self.inputs();
                let (bytes, offset): (&mut [u8], usize) = if index == obj::JOINT_INPUTS {
                    let _ = inputs.joints.pack(&mut image[..48]);
                    (
                        &mut image[..48],
                        [0, 12, 24, 36][usize::from(sub - 1).min(3)],
                    )
                } else {
                    let Some(t) = inputs.tactile else {
                        return Err(SdoAbort::GENERAL);
                    };
                    let _ = t.pack(&mut image[..60]);
                    (
                        &mut image[..60],
                        [0, 10, 20, 30, 50][usize::from(sub - 1).min(4)],
                    )
                };
                Ok(bytes[offset..offset + e.byte_len()].to_vec())
            }
            obj::MULTI_FINGER | obj::SINGLE_FINGER => {
                let bytes = self.last_outputs.to_array();
                let offsets: &[usize] = if index == obj::MULTI_FINGER {
                    &[0, 1, 13]
                } else {
                    &[25, 26, 27, 29]
                };
                let at = offsets
                    .get(usize::from(sub - 1))
                    .copied()
                    .ok_or(SdoAbort::SUBINDEX_DOES_NOT_EXIST)?;
                Ok(bytes[at..at + e.byte_len()].to_vec())
            }
            _ => Ok(self.values.get(&(index, sub)).cloned().unwrap_or_default()),
        }
    }

    fn sdo_write(
        &mut self,
        index: u16,
        sub: u8,
        data: &[u8],
        state: AlState,
    ) -> Result<(), SdoAbort> {
        if index == obj::SM2_ASSIGN || index == obj::SM3_ASSIGN {
            if state != AlState::PreOp {
                return Err(SdoAbort::STATE);
            }
            let allowed: &[u16] = if index == obj::SM2_ASSIGN {
                &[0x1600]
            } else {
                &[0x1A00, 0x1A01]
            };
            let assignment = self.assignment(index);
            return match (sub, data) {
                (0, [n, ..]) if usize::from(*n) <= assignment.len() => {
                    assignment.truncate(usize::from(*n));
                    Ok(())
                }
                (0, _) => Err(SdoAbort::VALUE_RANGE),
                (n, [lo, hi, ..]) if n >= 1 && usize::from(n) <= 4 => {
                    let pdo = u16::from_le_bytes([*lo, *hi]);
                    if !allowed.contains(&pdo) {
                        return Err(SdoAbort::VALUE_RANGE);
                    }
                    let i = usize::from(n) - 1;
                    if i < assignment.len() {
                        assignment[i] = pdo;
                    } else if i == assignment.len() {
                        assignment.push(pdo);
                    } else {
                        return Err(SdoAbort::SUBINDEX_DOES_NOT_EXIST);
                    }
                    Ok(())
                }
                _ => Err(SdoAbort::LENGTH_MISMATCH),
            };
        }
        let e = entry(index, sub).ok_or(if DICTIONARY.iter().any(|e| e.index == index) {
            SdoAbort::SUBINDEX_DOES_NOT_EXIST
        } else {
            SdoAbort::OBJECT_DOES_NOT_EXIST
        })?;
        if e.access == Access::Ro || is_live(index) {
            return Err(SdoAbort::READ_ONLY);
        }
        let value = if e.data_type.is_string() {
            if data.len() > e.byte_len() {
                return Err(SdoAbort::LENGTH_MISMATCH);
            }
            let end = data.iter().position(|&b| b == 0).unwrap_or(data.len());
            data[..end].to_vec()
        } else {
            // Expedited writes carry up to 4 bytes; numbers must have their exact size.
            if data.len() != e.byte_len() {
                return Err(SdoAbort::LENGTH_MISMATCH);
            }
            data.to_vec()
        };
        let byte = value.first().copied().unwrap_or(0);
        match (index, sub) {
            (obj::CONFIG, 0x01 | 0x05) if byte > 1 => return Err(SdoAbort::VALUE_RANGE),
            (obj::CONFIG, 0x15) if !matches!(byte, 1 | 2) => return Err(SdoAbort::VALUE_RANGE),
            (obj::CONFIG, 0x06) if byte == 1 => {
                // Manual position calibration: the fingers run to their open end stops.
                for j in 0..JOINTS {
                    self.hand.command(j, 2, 0.0, 500.0);
                }
            }
            _ => {}
        }
        self.values.insert((index, sub), value);
        Ok(())
    }

    fn process_image_sizes(&self) -> Result<(usize, usize), u16> {
        let outputs = teleop_revo2_protocol::image_len(&self.rx_assign)
            .filter(|_| self.rx_assign == [0x1600]);
        let inputs = Inputs::image_len(&self.tx_assign).ok();
        match (outputs, inputs) {
            (Some(o), Some(i)) => Ok((o, i)),
            (None, _) => Err(0x001D),
            (_, None) => Err(0x001E),
        }
    }

    fn write_outputs(&mut self, outputs: &[u8], now: Duration) {
        self.hand.advance_to(now.as_secs_f32());
        let Ok(decoded) = Outputs::unpack(outputs) else {
            return;
        };
        self.output_cycles += 1;
        // A command is applied when it changes: re-applying position+time every cycle would
        // restart the motion timer.
        if decoded != self.last_outputs {
            self.apply(&decoded);
            self.last_outputs = decoded;
        }
    }

    fn read_inputs(&mut self, inputs: &mut [u8], now: Duration) {
        self.hand.advance_to(now.as_secs_f32());
        let _ = self.inputs().pack(inputs, &self.tx_assign);
    }

    fn outputs_lost(&mut self) {
        self.hand.hold();
        self.last_outputs = Outputs::default();
        self.holds += 1;
    }

    fn transition(&mut self, from: AlState, to: AlState) -> Result<(), u16> {
        if from == AlState::Boot || to == AlState::Boot {
            self.upgrade.reset();
        }
        Ok(())
    }

    fn mailbox_request(
        &mut self,
        mailbox_type: u8,
        payload: &[u8],
        cx: &MailboxContext,
    ) -> MailboxReply {
        if mailbox_type != MAILBOX_FOE {
            return MailboxReply::Unsupported;
        }
        let file_type = self
            .value(FOE_FILE_TYPE.0, FOE_FILE_TYPE.1)
            .and_then(|v| v.first().copied())
            .unwrap_or(0);
        let auth = self.values.get(&FOE_AUTH_CODE).cloned().unwrap_or_default();
        self.upgrade.handle(payload, cx, file_type, &auth)
    }

    fn poll(&mut self, now: Duration, _state: AlState) -> AppRequest {
        match self.upgrade.poll(now) {
            Some((board, version)) => {
                self.restart_with(board, version);
                AppRequest::Restart {
                    offline: self.upgrade.timing.reboot,
                }
            }
            None => AppRequest::None,
        }
    }
}
