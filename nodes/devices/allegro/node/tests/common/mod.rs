//! The in-process rig of the Allegro loop tests: the node's driver on a local bus against a
//! scripted v3 hand, with a host that holds and records every cycle and every link loss.

use std::time::{Duration, Instant};

use teleop_allegro::driver::{self, Connected, Cycle, Down, Host, Target};
use teleop_allegro::{AllegroConfig, ProtocolSetting};
use teleop_allegro_protocol::Generation;
use teleop_can_link::local::LocalBus;
use teleop_can_link::CanLink;

/// A host that asks the hand to hold, records each cycle and why the link went down, and
/// stops `run_for` after it started.
pub struct Recorder {
    started: Instant,
    run_for: Duration,
    /// Every complete cycle, in order.
    pub cycles: Vec<Cycle>,
    /// Why the link went down, each time.
    pub downs: Vec<String>,
}

impl Host for Recorder {
    fn stop_requested(&self) -> bool {
        self.started.elapsed() >= self.run_for
    }
    fn target(&mut self) -> Target {
        Target::Hold
    }
    fn connected(&mut self, _: &Connected<'_>) -> anyhow::Result<()> {
        Ok(())
    }
    fn cycle(&mut self, cycle: &Cycle) -> anyhow::Result<()> {
        self.cycles.push(*cycle);
        Ok(())
    }
    fn link_down(&mut self, down: &Down<'_>) -> anyhow::Result<()> {
        self.downs.push(down.why.to_string());
        Ok(())
    }
}

/// Runs the node's driver for `run_for` against the v3 hand on `bus`, with `config` (whose link,
/// protocol and bring-up timeout this sets); returns what the host saw.
pub fn run_v3(bus: &LocalBus, config: AllegroConfig, run_for: Duration) -> Recorder {
    let settings = AllegroConfig {
        link: "local:/unused".into(),
        protocol: ProtocolSetting::Fixed(Generation::V3),
        bringup_timeout_ms: 500,
        ..config
    }
    .validate()
    .unwrap();
    let mut host = Recorder {
        started: Instant::now(),
        run_for,
        cycles: Vec::new(),
        downs: Vec::new(),
    };
    let mut open = || Ok(Box::new(bus.end()) as Box<dyn CanLink>);
    driver::run(&settings, &mut host, &mut open).unwrap();
    host
}
