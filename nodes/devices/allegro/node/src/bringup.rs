//! Bringing the hand up on an open link: drain, the generation's start sequence, the first
//! complete set of finger frames; detecting the generation (`protocol = "auto"`); naming a
//! hand that speaks the other generation or says nothing.

use std::time::{Duration, Instant};

use teleop_allegro_protocol::{detect, v4, Generation, Protocol, JOINTS};
use teleop_can_link::{CanFrame, CanLink, LinkError};

use crate::config::{ProtocolSetting, Settings};
use crate::gather::{Gather, Pushed};
use crate::wire::{Incoming, Wire};

/// Why the hand could not be brought up.
#[derive(Debug, thiserror::Error)]
pub enum BringUpError {
    /// The link failed.
    #[error(transparent)]
    Link(#[from] LinkError),
    /// Nothing on the bus, not even an answer to the other generation's start.
    #[error("{link}: no frames within {ms} ms: is the hand powered and the bit rate 1 Mbit/s?")]
    Silent {
        /// The link.
        link: String,
        /// How long the node listened after its start sequence.
        ms: u128,
    },
    /// The hand speaks the other protocol generation.
    #[error("{link}: saw {saw} IDs; set protocol = {fix}")]
    WrongGeneration {
        /// The link.
        link: String,
        /// The generation seen (`v4` or `v1-v3 (document protocol)`).
        saw: &'static str,
        /// The settings that fit.
        fix: &'static str,
        /// What was seen.
        protocol: Protocol,
    },
    /// `auto` found a document-protocol hand: its torque frames' joint order depends on the
    /// version, which its ids do not tell, so the node does not guess.
    #[error(
        "{link}: the hand speaks the document's protocol (v1-v3), whose torque joint order \
         differs between v1 and v2/v3: set protocol = v1, v2 or v3"
    )]
    DocumentProtocol {
        /// The link.
        link: String,
    },
    /// The hand answered but its four finger frames did not all come.
    #[error(
        "{link}: the hand answered ({frames} frames) but did not stream all four fingers' \
         positions within {ms} ms"
    )]
    NoStream {
        /// The link.
        link: String,
        /// Frames received.
        frames: u64,
        /// How long the node waited.
        ms: u128,
    },
}

impl BringUpError {
    /// Whether the hand is there but speaks the other generation (or, with `auto`, an ambiguous
    /// one): a setting to change, not a fault to wait out.
    pub fn is_setting(&self) -> bool {
        matches!(
            self,
            Self::WrongGeneration { .. } | Self::DocumentProtocol { .. }
        )
    }
}

fn wrong(link: &str, seen: Protocol) -> BringUpError {
    let (saw, fix) = match seen {
        Protocol::V4 => ("v4", "v4"),
        Protocol::Doc => ("v1-v3 (document protocol)", "v1, v2 or v3"),
    };
    BringUpError::WrongGeneration {
        link: link.to_string(),
        saw,
        fix,
        protocol: seen,
    }
}

/// What the hand told during bring-up.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Identity {
    /// v4: the info answer.
    pub info: Option<v4::Info>,
    /// v4: the serial number answer.
    pub serial: Option<[u8; 8]>,
    /// Document protocol: the QUERY_ID answer (revision, firmware, hardware type).
    pub doc_id: Option<(u16, u16, u8)>,
    /// v4: joint temperatures, deg C (None until a temperature frame of the finger came).
    pub temperatures: [Option<u8>; JOINTS],
    /// The joint positions of the first complete set, rad.
    pub positions: [f64; JOINTS],
}

impl Identity {
    /// Takes what an incoming frame says about the hand; true when it was such a frame.
    pub fn take(&mut self, incoming: &Incoming) -> bool {
        match *incoming {
            Incoming::Info(info) => self.info = Some(info),
            Incoming::Serial(s) => self.serial = Some(s),
            Incoming::DocId {
                revision,
                firmware,
                hw_type,
            } => self.doc_id = Some((revision, firmware, hw_type)),
            Incoming::Temperature { finger, celsius } => {
                let base = usize::from(finger) * 4;
                for (k, c) in celsius.iter().enumerate() {
                    if let Some(t) = self.temperatures.get_mut(base + k) {
                        *t = Some(*c);
                    }
                }
            }
            _ => return false,
        }
        true
    }
}

/// A hand brought up: its generation and what it said.
#[derive(Debug, Clone)]
pub struct Hand {
    /// The generation spoken.
    pub generation: Generation,
    /// What it told.
    pub identity: Identity,
}

/// Receives frames until `quiet` passes without one or `most` has passed; returns the protocol
/// the last identifiable frame belongs to and how many frames came.
fn drain(
    link: &mut dyn CanLink,
    quiet: Duration,
    most: Duration,
) -> Result<(Option<Protocol>, u64), LinkError> {
    let end = Instant::now() + most;
    let mut seen = None;
    let mut frames = 0;
    while let Some(left) = end.checked_duration_since(Instant::now()) {
        match link.recv(quiet.min(left))? {
            Some(frame) => {
                frames += 1;
                if let Some(p) = detect(&frame) {
                    seen = Some(p);
                }
            }
            None => break,
        }
    }
    Ok((seen, frames))
}

/// Sends a sequence with its pauses.
fn send_steps(link: &mut dyn CanLink, steps: &[crate::wire::Step]) -> Result<(), LinkError> {
    for s in steps {
        link.send(&s.frame)?;
        if !s.pause.is_zero() {
            std::thread::sleep(s.pause);
        }
    }
    Ok(())
}

fn send_all(link: &mut dyn CanLink, frames: &[CanFrame]) -> Result<(), LinkError> {
    frames.iter().try_for_each(|f| link.send(f))
}

/// Listens for `window`, decoding with `wire`, until `done` says so; returns frames received.
fn listen(
    link: &mut dyn CanLink,
    wire: &Wire,
    window: Duration,
    mut done: impl FnMut(&CanFrame, &Incoming) -> bool,
) -> Result<u64, LinkError> {
    let end = Instant::now() + window;
    let mut frames = 0;
    while let Some(left) = end.checked_duration_since(Instant::now()) {
        if let Some(frame) = link.recv(left)? {
            frames += 1;
            if done(&frame, &wire.decode(&frame)) {
                break;
            }
        }
    }
    Ok(frames)
}

fn probe_wire(protocol: Protocol, settings: &Settings) -> Wire {
    // The probes only read; the generation within a protocol does not matter for reading.
    let generation = match protocol {
        Protocol::Doc => Generation::V2,
        Protocol::V4 => Generation::V4,
    };
    Wire::new(generation, settings.device_id, settings.calibration)
}

/// Does a v4 hand answer the info query (it does whether streaming or not)?
fn probe_v4(
    link: &mut dyn CanLink,
    settings: &Settings,
    window: Duration,
) -> Result<bool, LinkError> {
    let wire = probe_wire(Protocol::V4, settings);
    if let Some(q) = wire.info_query() {
        link.send(&q)?;
    }
    let mut answered = false;
    listen(link, &wire, window, |frame, incoming| {
        answered = matches!(incoming, Incoming::Info(_)) || detect(frame) == Some(Protocol::V4);
        answered
    })?;
    Ok(answered)
}

/// Does a document-protocol hand stream after the document's start? Stops it again if so.
fn probe_doc(
    link: &mut dyn CanLink,
    settings: &Settings,
    window: Duration,
) -> Result<bool, LinkError> {
    let wire = probe_wire(Protocol::Doc, settings);
    send_steps(link, &wire.start_sequence(settings.period_ms, 0))?;
    let mut streamed = false;
    listen(link, &wire, window, |frame, incoming| {
        streamed =
            matches!(incoming, Incoming::Position { .. }) || detect(frame) == Some(Protocol::Doc);
        streamed
    })?;
    if streamed {
        send_all(link, &wire.stop_sequence())?;
    }
    Ok(streamed)
}

/// Which protocol the hand on `link` speaks: from what it streams already, else from its
/// answer to the v4 info query, else from its stream after the document's start sequence.
pub fn detect_protocol(
    link: &mut dyn CanLink,
    settings: &Settings,
) -> Result<Protocol, BringUpError> {
    let name = link.describe().to_string();
    let window = settings.bringup_timeout;
    if let (Some(p), _) = drain(link, Duration::from_millis(50), window)? {
        return Ok(p);
    }
    if probe_v4(link, settings, window.min(Duration::from_millis(200)))? {
        return Ok(Protocol::V4);
    }
    if probe_doc(link, settings, window)? {
        return Ok(Protocol::Doc);
    }
    Err(BringUpError::Silent {
        link: name,
        ms: window.as_millis() * 2,
    })
}

/// Brings the hand up as the setting says (`auto`: detected; a document-protocol hand is
/// refused with [`BringUpError::DocumentProtocol`] since its torque order cannot be told).
pub fn resolve(link: &mut dyn CanLink, settings: &Settings) -> Result<Hand, BringUpError> {
    match settings.protocol {
        ProtocolSetting::Fixed(g) => bring_up(link, g, settings),
        ProtocolSetting::Auto => match detect_protocol(link, settings)? {
            Protocol::V4 => bring_up(link, Generation::V4, settings),
            Protocol::Doc => Err(BringUpError::DocumentProtocol {
                link: link.describe().to_string(),
            }),
        },
    }
}

/// Brings a `generation` hand up: drains what the bus holds (naming a hand of the other
/// generation), sends the start sequence, and waits for all four finger frames (and, on v4,
/// the info answer). A silent hand is asked in the other generation's way, to name it.
pub fn bring_up(
    link: &mut dyn CanLink,
    generation: Generation,
    settings: &Settings,
) -> Result<Hand, BringUpError> {
    let name = link.describe().to_string();
    let wire = Wire::new(generation, settings.device_id, settings.calibration);
    let (seen, _) = drain(link, Duration::from_millis(20), Duration::from_millis(200))?;
    if let Some(p) = seen.filter(|p| *p != wire.protocol()) {
        return Err(wrong(&name, p));
    }
    send_steps(
        link,
        &wire.start_sequence(settings.period_ms, settings.temperature_period_ms),
    )?;
    let start = Instant::now();
    let deadline = start + settings.bringup_timeout;
    let mut identity = Identity::default();
    let mut gather = Gather::new();
    // Two complete sets make a stream (a document-protocol hand answers QUERY_STATE with one
    // set even when it does not stream).
    let mut sets = 0u32;
    let mut complete_at: Option<Instant> = None;
    let mut frames = 0u64;
    let mut foreign = None;
    while let Some(left) = deadline.checked_duration_since(Instant::now()) {
        // Once the stream is there, wait a little longer for the v4 info answer.
        if let Some(at) = complete_at {
            let want_info = wire.protocol() == Protocol::V4 && identity.info.is_none();
            if !want_info || at.elapsed() > Duration::from_millis(50) {
                break;
            }
        }
        let Some(frame) = link.recv(left.min(Duration::from_millis(10)))? else {
            continue;
        };
        frames += 1;
        let incoming = wire.decode(&frame);
        match incoming {
            Incoming::Position { finger, q } => {
                if gather.push(finger, q) == Pushed::Complete {
                    sets += 1;
                    identity.positions = *gather.positions();
                    if sets == 2 {
                        complete_at = Some(Instant::now());
                    }
                }
            }
            Incoming::Foreign(p) => foreign = Some(p),
            other => {
                identity.take(&other);
            }
        }
        if let Some(p) = foreign {
            return Err(wrong(&name, p));
        }
    }
    if complete_at.is_some() {
        return Ok(Hand {
            generation,
            identity,
        });
    }
    if frames > 0 {
        return Err(BringUpError::NoStream {
            link: name,
            frames,
            ms: start.elapsed().as_millis(),
        });
    }
    // Silent: is it a hand of the other generation?
    let window = settings.bringup_timeout.min(Duration::from_millis(300));
    match wire.protocol() {
        Protocol::Doc => {
            if probe_v4(link, settings, window)? {
                return Err(wrong(&name, Protocol::V4));
            }
        }
        Protocol::V4 => {
            if probe_doc(link, settings, window)? {
                return Err(wrong(&name, Protocol::Doc));
            }
        }
    }
    Err(BringUpError::Silent {
        link: name,
        ms: start.elapsed().as_millis(),
    })
}

/// Stops the hand: zero torque, then the stop sequence (SYSTEM_OFF). Errors are returned after
/// every frame was tried.
pub fn shut_down(link: &mut dyn CanLink, wire: &Wire) -> Result<(), LinkError> {
    let mut first_error = None;
    for frame in wire
        .zero_torque_frames()
        .iter()
        .chain(wire.stop_sequence().iter())
    {
        if let Err(e) = link.send(frame) {
            first_error.get_or_insert(e);
        }
    }
    first_error.map_or(Ok(()), Err)
}
