//! The node's loop (`teleop_leap::driver::run_on`) on a recording line: sixteen servos that
//! answer what the requests ask, keep a control table each, refuse EEPROM writes while their
//! torque is on (Access Error, as the ROBOTIS e-manual says), and start with the torque on (a
//! crashed earlier session; one with the settings another tool left). What the loop wrote, in
//! order, shows the bring-up as docs/devices/leap.md gives it: torque off before any EEPROM
//! write, Operating Mode 5, Drive Mode and Homing Offset 0 where they differ, Return Delay
//! Time, the gains, the profiles 0 where they differ, Goal Current, the goal at the present
//! position (no jump), torque on last; then one Sync Write of the goals and one Fast Sync Read
//! per cycle; torque off on stop, broadcast first. A servo that refuses a step leaves every
//! servo's torque off.
#![allow(clippy::unwrap_used)]

use std::collections::VecDeque;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use teleop_hand_profile::HandProfile;
use teleop_leap::bus::Line;
use teleop_leap::driver::{self, Connected, Cycle, Down, Host, Target};
use teleop_leap::LeapConfig;
use teleop_leap_protocol::packet::{self, instruction, Request, Scan};
use teleop_leap_protocol::xc330;

/// What the loop asked of the servos: `(id, instruction, addr, data)`.
type Record = (u8, u8, u16, Vec<u8>);

/// Sixteen servos behind a line, answering at once; what they were asked goes to `log`.
struct Servos {
    tables: Vec<[u8; 256]>,
    pending: VecDeque<u8>,
    log: Arc<Mutex<Vec<Record>>>,
    /// A servo refusing writes at an address (Data Limit Error).
    refuse: Option<(u8, u16)>,
    /// A servo that neither hears nor answers while set.
    deaf: Arc<Mutex<Option<u8>>>,
}

impl Servos {
    fn new(log: Arc<Mutex<Vec<Record>>>) -> Self {
        let mut table = [0u8; 256];
        table[0..2].copy_from_slice(&1240u16.to_le_bytes());
        table[6] = 52;
        table[9] = 250; // Return Delay Time: the factory's 500 us
        table[11] = 3; // Operating Mode: position (the factory's)
        table[64] = 1; // torque on, left so by an earlier session
        table[132..136].copy_from_slice(&1500i32.to_le_bytes());
        let mut tables = vec![table; 16];
        // Servo 2 as another tool left it: reversed, offset, with a profile.
        tables[2][10] = 1;
        tables[2][20..24].copy_from_slice(&100i32.to_le_bytes());
        tables[2][112..116].copy_from_slice(&50u32.to_le_bytes());
        Self {
            tables,
            pending: VecDeque::new(),
            log,
            refuse: None,
            deaf: Arc::new(Mutex::new(None)),
        }
    }

    fn status(&mut self, id: u8, error: u8, params: &[u8]) {
        let mut out = [0u8; 600];
        let n = packet::status(id, error, params, &mut out).unwrap();
        self.pending.extend(&out[..n]);
    }

    fn take(&mut self, raw: &[u8]) {
        let mut scratch = [0u8; 1100];
        let p = packet::parse(raw, &mut scratch).unwrap();
        let id = p.id;
        let deaf = *self.deaf.lock().unwrap();
        if deaf == Some(id) {
            return;
        }
        match Request::from_packet(&p).unwrap() {
            Request::Ping => {
                let t = self.tables[usize::from(id)];
                self.status(id, 0, &[t[0], t[1], t[6]]);
            }
            Request::Read { addr, len } => {
                let t = self.tables[usize::from(id)];
                let (a, l) = (usize::from(addr), usize::from(len));
                self.status(id, 0, &t[a..a + l]);
            }
            Request::Write { addr, data } if id == packet::BROADCAST_ID => {
                // Carried out by every servo, answered by none.
                self.log
                    .lock()
                    .unwrap()
                    .push((id, instruction::WRITE, addr, data.to_vec()));
                let a = usize::from(addr);
                for t in &mut self.tables {
                    if addr >= xc330::RAM_START || t[64] == 0 {
                        t[a..a + data.len()].copy_from_slice(data);
                    }
                }
            }
            Request::Write { addr, data } => {
                self.log
                    .lock()
                    .unwrap()
                    .push((id, instruction::WRITE, addr, data.to_vec()));
                if self.refuse == Some((id, addr)) {
                    self.status(id, 6, &[]);
                    return;
                }
                let t = &mut self.tables[usize::from(id)];
                if addr < xc330::RAM_START && t[64] == 1 {
                    self.status(id, 7, &[]);
                    return;
                }
                let a = usize::from(addr);
                t[a..a + data.len()].copy_from_slice(data);
                self.status(id, 0, &[]);
            }
            Request::SyncWrite { addr, items, .. } => {
                for (id, data) in items.iter() {
                    self.log.lock().unwrap().push((
                        id,
                        instruction::SYNC_WRITE,
                        addr,
                        data.to_vec(),
                    ));
                }
            }
            Request::FastSyncRead { addr, len, ids } => {
                self.log.lock().unwrap().push((
                    0xFE,
                    instruction::FAST_SYNC_READ,
                    addr,
                    ids.to_vec(),
                ));
                let (a, l) = (usize::from(addr), usize::from(len));
                let tables = &self.tables;
                let blocks = ids
                    .iter()
                    .filter(|id| Some(**id) != deaf)
                    .map(|id| (*id, 0u8, &tables[usize::from(*id)][a..a + l]));
                let mut out = [0u8; 600];
                let n = packet::fast_sync_status(blocks, &mut out).unwrap();
                self.pending.extend(&out[..n]);
            }
            other => panic!("the loop sent {other:?}"),
        }
    }
}

impl Line for Servos {
    fn send(&mut self, bytes: &[u8]) -> std::io::Result<()> {
        let mut at = 0;
        while at < bytes.len() {
            match packet::scan(&bytes[at..]) {
                Scan::Packet(n) => {
                    self.take(&bytes[at..at + n]);
                    at += n;
                }
                other => panic!("the loop sent a broken packet: {other:?}"),
            }
        }
        Ok(())
    }

    fn recv(&mut self, buf: &mut [u8], _: Duration) -> std::io::Result<usize> {
        let n = self.pending.len().min(buf.len());
        for (b, v) in buf.iter_mut().zip(self.pending.drain(..n)) {
            *b = v;
        }
        Ok(n)
    }
}

/// Holds for a number of cycles, then stops.
struct Cycles {
    left: u32,
    seen: u32,
}

impl Host for Cycles {
    fn stop_requested(&self) -> bool {
        self.left == 0
    }
    fn target(&mut self) -> Target {
        Target::Hold
    }
    fn connected(&mut self, _: &Connected<'_>) -> anyhow::Result<()> {
        Ok(())
    }
    fn cycle(&mut self, cycle: &Cycle<'_>) -> anyhow::Result<()> {
        self.left -= 1;
        self.seen += 1;
        assert_eq!(cycle.servos.fresh(), 0xFFFF, "every servo read");
        assert_eq!(cycle.servos.reading(3).position, 1500);
        Ok(())
    }
    fn link_down(&mut self, down: &Down<'_>) -> anyhow::Result<()> {
        anyhow::bail!("down: {}", down.why)
    }
}

#[test]
fn bring_up_in_the_documented_order_then_one_write_and_one_read_per_cycle() {
    let settings = LeapConfig::default().validate().unwrap();
    let profile = HandProfile::builtin("leap").unwrap();
    let log = Arc::new(Mutex::new(Vec::new()));
    let mut line = Some(Servos::new(log.clone()));
    let mut open = move || line.take().ok_or_else(|| "opened twice".to_string());
    let mut host = Cycles { left: 5, seen: 0 };
    driver::run_on(&settings, &profile, &mut host, &mut open).unwrap();
    assert_eq!(host.seen, 5);
    let log = log.lock().unwrap().clone();

    for id in 0..16u8 {
        let writes: Vec<(u16, Vec<u8>)> = log
            .iter()
            .filter(|r| r.0 == id && r.1 == instruction::WRITE)
            .map(|r| (r.2, r.3.clone()))
            .collect();
        let (p, i, d) = if [0, 4, 8].contains(&id) {
            (450u16, 0u16, 150u16)
        } else {
            (600, 0, 200)
        };
        let mut gains = Vec::new();
        for g in [d, i, p] {
            gains.extend(g.to_le_bytes());
        }
        let mut want = vec![
            (xc330::TORQUE_ENABLE, vec![0]),
            (xc330::OPERATING_MODE, vec![5]),
            (xc330::RETURN_DELAY_TIME, vec![0]),
            (xc330::POSITION_D_GAIN, gains),
            (xc330::GOAL_CURRENT, 350u16.to_le_bytes().to_vec()),
            (xc330::GOAL_POSITION, 1500i32.to_le_bytes().to_vec()),
            (xc330::TORQUE_ENABLE, vec![1]),
            (xc330::TORQUE_ENABLE, vec![0]),
        ];
        if id == 2 {
            // What another tool left, set back with the torque off.
            want.insert(2, (xc330::DRIVE_MODE, vec![0]));
            want.insert(4, (xc330::HOMING_OFFSET, vec![0; 4]));
            want.insert(6, (xc330::PROFILE_ACCELERATION, vec![0; 8]));
        }
        assert_eq!(writes, want, "servo {id}");
    }
    // Stop: one broadcast torque off after the last cycle, then each servo confirmed.
    let broadcast: Vec<usize> = log
        .iter()
        .enumerate()
        .filter(|(_, r)| r.0 == packet::BROADCAST_ID && r.1 == instruction::WRITE)
        .map(|(k, _)| k)
        .collect();
    assert_eq!(broadcast.len(), 1);
    assert_eq!(log[broadcast[0]].2, xc330::TORQUE_ENABLE);
    let last_read = log
        .iter()
        .rposition(|r| r.1 == instruction::FAST_SYNC_READ)
        .unwrap();
    assert!(broadcast[0] > last_read);
    // Every servo's bring-up steps run before any cycle; torque on is the last of them.
    let last_on = log
        .iter()
        .rposition(|r| r.1 == instruction::WRITE && r.3 == [1])
        .unwrap();
    let first_cycle = log
        .iter()
        .position(|r| r.1 == instruction::SYNC_WRITE)
        .unwrap();
    assert!(last_on < first_cycle);
    // Each cycle: one Sync Write of the 16 goals (held: where the hand was), one Fast Sync
    // Read of the state of all 16.
    let cycles: Vec<&Record> = log[first_cycle..]
        .iter()
        .filter(|r| r.1 != instruction::WRITE)
        .collect();
    assert_eq!(cycles.len(), 5 * 17);
    for c in cycles.chunks(17) {
        assert!(c[..16].iter().all(|r| r.1 == instruction::SYNC_WRITE
            && r.2 == xc330::GOAL_POSITION
            && r.3 == 1500i32.to_le_bytes()));
        assert_eq!(c[16].1, instruction::FAST_SYNC_READ);
        assert_eq!((c[16].2, c[16].3.len()), (xc330::STATE_ADDR, 16));
    }
}

/// Gives up at the first report that the hand is down.
struct Down1;

impl Host for Down1 {
    fn stop_requested(&self) -> bool {
        false
    }
    fn target(&mut self) -> Target {
        Target::Hold
    }
    fn connected(&mut self, _: &Connected<'_>) -> anyhow::Result<()> {
        anyhow::bail!("the hand came up")
    }
    fn cycle(&mut self, _: &Cycle<'_>) -> anyhow::Result<()> {
        Ok(())
    }
    fn link_down(&mut self, down: &Down<'_>) -> anyhow::Result<()> {
        anyhow::bail!("down: {}", down.why)
    }
}

#[test]
fn a_servo_refusing_a_step_leaves_every_servo_torque_off() {
    let settings = LeapConfig::default().validate().unwrap();
    let profile = HandProfile::builtin("leap").unwrap();
    let log = Arc::new(Mutex::new(Vec::new()));
    let mut servos = Servos::new(log.clone());
    // Servo 5's Current Limit below the Goal Current asked (another tool lowered it).
    servos.refuse = Some((5, xc330::GOAL_CURRENT));
    let tables = Arc::new(Mutex::new(Vec::new()));
    let mut line = Some(Recorded(servos, tables.clone()));
    let mut open = move || line.take().ok_or_else(|| "opened twice".to_string());
    let err = driver::run_on(&settings, &profile, &mut Down1, &mut open).unwrap_err();
    let err = err.to_string();
    assert!(
        err.contains("middle_mcp_forward (id 5): Goal Current refused"),
        "{err}"
    );
    let log = log.lock().unwrap().clone();
    assert!(
        !log.iter()
            .any(|r| r.1 == instruction::WRITE && r.2 == xc330::TORQUE_ENABLE && r.3 == [1]),
        "no torque on: {log:?}"
    );
    let tables = tables.lock().unwrap();
    assert!(tables.iter().all(|t| t[64] == 0), "every torque off");
}

/// The servos' line, their tables copied out when the loop drops it.
struct Recorded(Servos, Arc<Mutex<Vec<[u8; 256]>>>);

impl Drop for Recorded {
    fn drop(&mut self) {
        *self.1.lock().unwrap() = self.0.tables.clone();
    }
}

impl Line for Recorded {
    fn send(&mut self, bytes: &[u8]) -> std::io::Result<()> {
        self.0.send(bytes)
    }
    fn recv(&mut self, buf: &mut [u8], timeout: Duration) -> std::io::Result<usize> {
        self.0.recv(buf, timeout)
    }
}

/// Makes servo 9 deaf at the third cycle and hears again at the tenth; stops once it is back
/// in the reads after having been taken for silent.
struct Deaf {
    deaf: Arc<Mutex<Option<u8>>>,
    cycles: u32,
    /// Servo 9 was taken for silent (so `back` means it came back, not that it never left).
    was_silent: bool,
    back: bool,
}

impl Host for Deaf {
    fn stop_requested(&self) -> bool {
        self.back || self.cycles > 5000
    }
    fn target(&mut self) -> Target {
        Target::Hold
    }
    fn connected(&mut self, _: &Connected<'_>) -> anyhow::Result<()> {
        Ok(())
    }
    fn cycle(&mut self, cycle: &Cycle<'_>) -> anyhow::Result<()> {
        self.cycles += 1;
        self.was_silent |= cycle.servos.silent() & (1 << 9) != 0;
        match self.cycles {
            3 => *self.deaf.lock().unwrap() = Some(9),
            10 => *self.deaf.lock().unwrap() = None,
            n if n > 10 => self.back = self.was_silent && cycle.servos.silent() == 0,
            _ => {}
        }
        Ok(())
    }
    fn link_down(&mut self, down: &Down<'_>) -> anyhow::Result<()> {
        anyhow::bail!("down: {}", down.why)
    }
}

#[test]
fn a_servo_back_from_silence_with_its_torque_on_only_gets_its_goal_set() {
    let config = LeapConfig {
        silent_retry_ms: 10,
        ..LeapConfig::default()
    };
    let settings = config.validate().unwrap();
    let profile = HandProfile::builtin("leap").unwrap();
    let log = Arc::new(Mutex::new(Vec::new()));
    let servos = Servos::new(log.clone());
    let mut host = Deaf {
        deaf: servos.deaf.clone(),
        cycles: 0,
        was_silent: false,
        back: false,
    };
    let mut line = Some(servos);
    let mut open = move || line.take().ok_or_else(|| "opened twice".to_string());
    driver::run_on(&settings, &profile, &mut host, &mut open).unwrap();
    assert!(host.was_silent, "servo 9 taken for silent");
    assert!(host.back, "servo 9 back in the reads");
    let log = log.lock().unwrap().clone();
    let first_cycle = log
        .iter()
        .position(|r| r.1 == instruction::SYNC_WRITE)
        .unwrap();
    // Between the bring-up and the stop's broadcast, servo 9 got one write: its goal where it
    // is (its torque never off: no limp moment).
    let stop = log
        .iter()
        .position(|r| r.0 == packet::BROADCAST_ID && r.1 == instruction::WRITE)
        .unwrap();
    let writes: Vec<&Record> = log[first_cycle..stop]
        .iter()
        .filter(|r| r.0 == 9 && r.1 == instruction::WRITE)
        .collect();
    assert_eq!(
        writes,
        [&(
            9,
            instruction::WRITE,
            xc330::GOAL_POSITION,
            1500i32.to_le_bytes().to_vec()
        )]
    );
}

/// Makes servo 9 deaf from the third cycle for `deaf_for` cycles; records the cycles in which
/// it was taken for silent.
struct Briefly {
    deaf: Arc<Mutex<Option<u8>>>,
    deaf_for: u32,
    cycles: u32,
    silent_at: Vec<u32>,
}

impl Host for Briefly {
    fn stop_requested(&self) -> bool {
        self.cycles >= 20
    }
    fn target(&mut self) -> Target {
        Target::Hold
    }
    fn connected(&mut self, _: &Connected<'_>) -> anyhow::Result<()> {
        Ok(())
    }
    fn cycle(&mut self, cycle: &Cycle<'_>) -> anyhow::Result<()> {
        self.cycles += 1;
        if cycle.servos.silent() != 0 {
            self.silent_at.push(self.cycles);
        }
        if self.cycles == 2 {
            *self.deaf.lock().unwrap() = Some(9);
        }
        if self.cycles == 2 + self.deaf_for {
            *self.deaf.lock().unwrap() = None;
        }
        Ok(())
    }
    fn link_down(&mut self, down: &Down<'_>) -> anyhow::Result<()> {
        anyhow::bail!("down: {}", down.why)
    }
}

#[test]
fn a_servo_is_silent_only_after_missing_several_cycles_in_a_row() {
    let settings = LeapConfig::default().validate().unwrap();
    let profile = HandProfile::builtin("leap").unwrap();
    let run = |deaf_for: u32| {
        let servos = Servos::new(Arc::new(Mutex::new(Vec::new())));
        let mut host = Briefly {
            deaf: servos.deaf.clone(),
            deaf_for,
            cycles: 0,
            silent_at: Vec::new(),
        };
        let mut line = Some(servos);
        let mut open = move || line.take().ok_or_else(|| "opened twice".to_string());
        driver::run_on(&settings, &profile, &mut host, &mut open).unwrap();
        host.silent_at
    };
    // Missing fewer cycles than SILENT_AFTER (a late reply, a burst of noise): never left out.
    let brief = run(u32::from(driver::SILENT_AFTER) - 1);
    assert!(brief.is_empty(), "taken for silent at cycles {brief:?}");
    // Missing longer: left out from the cycle its SILENT_AFTER-th miss is found.
    let long = run(10);
    assert_eq!(
        long.first(),
        Some(&(2 + u32::from(driver::SILENT_AFTER))),
        "{long:?}"
    );
}
