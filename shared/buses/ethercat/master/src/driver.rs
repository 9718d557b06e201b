//! What a device brings to the master: the [`Driver`] trait, and the [`Image`] its process data
//! is packed into and unpacked from.

use std::future::Future;
use std::ops::Range;
use std::time::Duration;

use ethercrab::MainDevice;

use crate::bus::{Found, OpGroup, PreOpGroup, MAX_PDI, MAX_SUBDEVICES};

/// One direction of the process data of every SubDevice on the bus (all outputs, or all
/// inputs), in bus order; a SubDevice without process data in that direction has an empty
/// part. The master copies it to and from ethercrab's process image, so a driver never holds
/// ethercrab's image lock.
#[derive(Debug, Clone)]
pub struct Image {
    bytes: [u8; MAX_PDI],
    ranges: [Range<usize>; MAX_SUBDEVICES],
    count: usize,
}

impl Image {
    /// An image with parts of these lengths, in bus order. Lengths past [`MAX_SUBDEVICES`] or
    /// [`MAX_PDI`] bytes in all are cut (ethercrab's group cannot hold more).
    pub fn with_lengths(lengths: impl IntoIterator<Item = usize>) -> Self {
        let mut image = Self {
            bytes: [0; MAX_PDI],
            ranges: Default::default(),
            count: 0,
        };
        let mut at = 0;
        for (range, len) in image.ranges.iter_mut().zip(lengths) {
            let end = (at + len).min(MAX_PDI);
            *range = at..end;
            at = end;
            image.count += 1;
        }
        image
    }

    /// How many SubDevices the image has a part for.
    pub fn len(&self) -> usize {
        self.count
    }

    /// True without any part.
    pub fn is_empty(&self) -> bool {
        self.count == 0
    }

    /// The part of SubDevice `index` (empty for a SubDevice that is not on the bus).
    pub fn subdevice(&self, index: usize) -> &[u8] {
        match self.ranges[..self.count].get(index) {
            Some(r) => &self.bytes[r.clone()],
            None => &[],
        }
    }

    /// The part of SubDevice `index`, to write (empty for a SubDevice that is not on the bus).
    pub fn subdevice_mut(&mut self, index: usize) -> &mut [u8] {
        match self.ranges[..self.count].get(index) {
            Some(r) => &mut self.bytes[r.clone()],
            None => &mut [],
        }
    }
}

/// Process data a driver lays out itself, for a device whose SII announces no PDOs or sync
/// managers (the Shadow palm): its [`Driver::configure`] programs the sync managers and FMMUs,
/// and the master exchanges one LRW over the logical range: each SubDevice's outputs, then its
/// inputs, in bus order (inputs sent as zeros, so a byte the device did not refill reads 0).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct OwnLayout {
    /// Logical address of the first byte.
    pub logical_start: u32,
    /// Output and input bytes of each SubDevice, in bus order.
    pub parts: Vec<(usize, usize)>,
    /// Working counter of an exchange in which every output was taken and every input fresh.
    pub expected_wkc: u16,
}

impl OwnLayout {
    /// Bytes of the LRW.
    pub fn len(&self) -> usize {
        self.parts.iter().map(|(o, i)| o + i).sum()
    }

    /// True without any byte.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// One LRW over an [`OwnLayout`]: what the cycle exchanges for such a driver, and what a tool
/// that drives the device outside the cycle (the Shadow palm's CAN direct mode) exchanges.
#[derive(Debug, Clone)]
pub struct OwnExchange {
    layout: OwnLayout,
    frame: Vec<u8>,
}

impl OwnExchange {
    /// An exchange over `layout` (outputs zero until written).
    pub fn new(layout: OwnLayout) -> Self {
        Self {
            frame: vec![0; layout.len()],
            layout,
        }
    }

    /// The layout.
    pub fn layout(&self) -> &OwnLayout {
        &self.layout
    }

    /// Output and input images with a part per SubDevice of the layout.
    pub fn images(&self) -> (Image, Image) {
        (
            Image::with_lengths(self.layout.parts.iter().map(|p| p.0)),
            Image::with_lengths(self.layout.parts.iter().map(|p| p.1)),
        )
    }

    /// Puts the outputs where the next exchange sends them.
    pub fn write(&mut self, outputs: &Image) {
        let mut at = 0;
        for (i, (o, n)) in self.layout.parts.iter().enumerate() {
            let part = outputs.subdevice(i);
            let len = part.len().min(*o);
            self.frame[at..at + len].copy_from_slice(&part[..len]);
            at += o + n;
        }
    }

    /// Sends the LRW (inputs as zeros, so a byte the device did not refill reads 0) and copies
    /// the inputs that came back into `inputs`; the working counter it came back with. With
    /// another working counter than the layout's, ethercrab does not hand the data back: the
    /// inputs then read as zeros.
    pub async fn exchange(
        &mut self,
        md: &MainDevice<'static>,
        inputs: &mut Image,
    ) -> Result<u16, ethercrab::error::Error> {
        self.zero_inputs();
        let sent = ethercrab::Command::lrw(self.layout.logical_start)
            .with_wkc(self.layout.expected_wkc)
            .send_receive_slice(md, &self.frame[..])
            .await;
        match sent {
            Ok(pdu) => {
                self.copy_inputs(Some(&pdu), inputs);
                Ok(self.layout.expected_wkc)
            }
            Err(ethercrab::error::Error::WorkingCounter { received, .. }) => {
                self.copy_inputs(None, inputs);
                Ok(received)
            }
            Err(e) => Err(e),
        }
    }

    /// Like [`exchange`](Self::exchange), but hands back the inputs whatever the working
    /// counter (which ethercrab then does not report): for a tool that judges freshness by
    /// content, each input byte the device did not refill reading 0.
    pub async fn exchange_any(
        &mut self,
        md: &MainDevice<'static>,
        inputs: &mut Image,
    ) -> Result<(), ethercrab::error::Error> {
        self.zero_inputs();
        let pdu = ethercrab::Command::lrw(self.layout.logical_start)
            .ignore_wkc()
            .send_receive_slice(md, &self.frame[..])
            .await?;
        self.copy_inputs(Some(&pdu), inputs);
        Ok(())
    }

    fn zero_inputs(&mut self) {
        let mut at = 0;
        for (o, n) in &self.layout.parts {
            self.frame[at + o..at + o + n].fill(0);
            at += o + n;
        }
    }

    fn copy_inputs(&self, data: Option<&[u8]>, inputs: &mut Image) {
        let mut at = 0;
        for (i, (o, n)) in self.layout.parts.iter().enumerate() {
            let part = inputs.subdevice_mut(i);
            match data.and_then(|d| d.get(at + o..at + o + n)) {
                Some(src) if src.len() == part.len() => part.copy_from_slice(src),
                _ => part.fill(0),
            }
            at += o + n;
        }
    }
}

/// A device on the bus, as the master drives it: which SubDevices it is, how it is configured
/// in PRE-OP, and how commands and inputs map to its process data. Everything else (the cycle,
/// deadlines, working counter and AL-state checks, recovery, reconnect, hold when the host has
/// no command, counters) is the master's: see [`crate::run`].
///
/// `pack`, `unpack` and `hold` run inside the cycle: no allocation, no blocking, no logging
/// that can block.
pub trait Driver {
    /// What the device is told each cycle (e.g. a hand command).
    type Command;
    /// What the device's inputs decode to.
    type Inputs;
    /// What the side channel reads (see [`poll_period`](Self::poll_period)).
    type Polled: Copy + Send;

    /// The device's name in logs and errors ("Revo2").
    fn name(&self) -> &str;

    /// Checks that the bus holds this device: `found` is every SubDevice, in bus order (empty
    /// when the bus has none). A foreign identity is refused with an error naming what was
    /// found (vendor, product, name) and what was expected.
    fn identify(&self, found: &[Found]) -> anyhow::Result<()>;

    /// Configures the device in PRE-OP (SDO writes, PDO assignment and mapping) through the
    /// group's SubDevice handles, and keeps what it learns. The master then goes to OP, where
    /// ethercrab sizes the process data from the PDO assignment.
    fn configure(
        &mut self,
        md: &MainDevice<'static>,
        group: &PreOpGroup,
    ) -> impl Future<Output = anyhow::Result<()>>;

    /// Writes `command` into the outputs; false when the device cannot take it (the master then
    /// holds and reports [`Event::Refused`](crate::Event::Refused)). Commands come admitted by
    /// the host (checked and within the joint limits): a driver converts, it does not judge.
    fn pack(&mut self, command: &Self::Command, outputs: &mut Image) -> bool;

    /// Decodes the inputs of a cycle whose working counter was right; `polled` is the side
    /// channel's latest reading when it runs and has read something. `None`: the inputs are
    /// unusable (counted with the wrong working counters).
    fn unpack(&mut self, inputs: &Image, polled: Option<&Self::Polled>) -> Option<Self::Inputs>;

    /// Writes the outputs that hold the device: sent when the host has no command (stale, the
    /// e-stop, refused), and for a few cycles before the master leaves OP. A
    /// driver holds the last commanded target where it has one, so that a grasp keeps its
    /// grip; `last` (where the device is) is for when it has none. `last` is `None` only for a
    /// driver that holds [every cycle](Self::hold_every_cycle), before its first inputs.
    fn hold(&mut self, last: Option<&Self::Inputs>, outputs: &mut Image);

    /// True for a device the host closes the loop for (the Shadow palm: its demands come from
    /// the host's position control every cycle): [`hold`](Self::hold) is then called every
    /// cycle the host gives no command, not once, and also before the first inputs came.
    fn hold_every_cycle(&self) -> bool {
        false
    }

    /// The process data layout when the driver programs it itself (see [`OwnLayout`]); `None`
    /// (the default): ethercrab's, from the PDO assignment. Asked after
    /// [`configure`](Self::configure).
    fn own_layout(&self) -> Option<OwnLayout> {
        None
    }

    /// How often the side channel runs, or `None` (the default) for none. The side channel is
    /// [`poll`](Self::poll), called on a thread of its own while the device is in OP, so that a
    /// slow or failing mailbox never delays the cycle (e.g. data read by SDO because the device
    /// cannot put it in its process data).
    fn poll_period(&self) -> Option<Duration> {
        None
    }

    /// One reading of the side channel (only called when [`poll_period`](Self::poll_period) is
    /// `Some`). May block on the mailbox; a panic inside ethercrab is caught and logged. A
    /// driver without a side channel keeps the default, which says so.
    fn poll(md: &MainDevice<'static>, group: &OpGroup) -> anyhow::Result<Self::Polled> {
        let _ = (md, group);
        anyhow::bail!("this driver has no side channel")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parts_follow_each_other_and_unknown_subdevices_are_empty() {
        let mut image = Image::with_lengths([0, 3, 2]);
        assert_eq!(image.len(), 3);
        assert!(image.subdevice(0).is_empty());
        image.subdevice_mut(1).copy_from_slice(&[1, 2, 3]);
        image.subdevice_mut(2).copy_from_slice(&[4, 5]);
        assert_eq!(image.subdevice(1), &[1, 2, 3]);
        assert_eq!(image.subdevice(2), &[4, 5]);
        assert!(image.subdevice(3).is_empty() && image.subdevice_mut(9).is_empty());
    }

    #[test]
    fn lengths_beyond_the_group_are_cut() {
        let image = Image::with_lengths([MAX_PDI - 1, 10, 1, 1, 1]);
        assert_eq!(image.len(), MAX_SUBDEVICES);
        assert_eq!(image.subdevice(0).len(), MAX_PDI - 1);
        assert_eq!(image.subdevice(1).len(), 1);
        assert!(image.subdevice(2).is_empty());
    }
}
