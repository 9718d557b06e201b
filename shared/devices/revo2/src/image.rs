//! Process images: the RxPDO (outputs) and the TxPDOs (inputs), packed and
//! unpacked without heap, little-endian and tightly packed in mapping order.

use crate::dictionary::{mapping_bits, obj, JOINT_TX_MAPPING, RX_MAPPING, TACTILE_TX_MAPPING};
use crate::identity::{Joint, FINGERTIPS, JOINTS};
use crate::ControlMode;

/// Bytes of the RxPDO 0x1600 image: mode, 6 x param1, 6 x param2 (multi),
/// mode, joint, param1, param2 (single). No padding.
pub const RX_LEN: usize = 1 + 12 + 12 + 1 + 1 + 2 + 2;
/// Bytes of the joint-data TxPDO 0x1A00 image.
pub const JOINT_TX_LEN: usize = 48;
/// Bytes of the tactile TxPDO 0x1A01 image.
pub const TACTILE_TX_LEN: usize = 60;

const _: () = assert!(RX_LEN * 8 == mapping_bits(RX_MAPPING));
const _: () = assert!(JOINT_TX_LEN * 8 == mapping_bits(JOINT_TX_MAPPING));
const _: () = assert!(TACTILE_TX_LEN * 8 == mapping_bits(TACTILE_TX_MAPPING));

/// Why a process image could not be packed or unpacked.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum ImageError {
    /// The buffer does not have the image's exact length.
    #[error("process image has {got} bytes, expected {expected}")]
    WrongLength {
        /// Length of the image.
        expected: usize,
        /// Length of the buffer.
        got: usize,
    },
    /// The assignment names a PDO this direction does not have.
    #[error("unknown PDO 0x{0:04X} in the assignment")]
    UnknownPdo(u16),
    /// The assignment lacks a PDO the image needs (the joint data 0x1A00).
    #[error("PDO 0x{0:04X} missing from the assignment")]
    MissingPdo(u16),
    /// The assignment names a PDO twice.
    #[error("PDO 0x{0:04X} assigned twice")]
    DuplicatePdo(u16),
}

fn check_len(expected: usize, got: usize) -> Result<(), ImageError> {
    if expected == got {
        Ok(())
    } else {
        Err(ImageError::WrongLength { expected, got })
    }
}

/// Sequential little-endian reader. Callers check the length first; reading
/// past the end yields zeros instead of panicking.
struct Reader<'a> {
    rest: &'a [u8],
}

impl<'a> Reader<'a> {
    fn new(bytes: &'a [u8]) -> Self {
        Reader { rest: bytes }
    }

    fn take<const N: usize>(&mut self) -> [u8; N] {
        match self.rest.split_first_chunk::<N>() {
            Some((head, tail)) => {
                self.rest = tail;
                *head
            }
            None => {
                self.rest = &[];
                [0; N]
            }
        }
    }

    fn u8(&mut self) -> u8 {
        u8::from_le_bytes(self.take())
    }

    fn u16(&mut self) -> u16 {
        u16::from_le_bytes(self.take())
    }

    fn i16(&mut self) -> i16 {
        i16::from_le_bytes(self.take())
    }

    fn u32(&mut self) -> u32 {
        u32::from_le_bytes(self.take())
    }

    fn u16s<const N: usize>(&mut self) -> [u16; N] {
        core::array::from_fn(|_| self.u16())
    }

    fn i16s<const N: usize>(&mut self) -> [i16; N] {
        core::array::from_fn(|_| self.i16())
    }

    fn u32s<const N: usize>(&mut self) -> [u32; N] {
        core::array::from_fn(|_| self.u32())
    }
}

/// Sequential little-endian writer. Callers check the length first; writes
/// past the end are dropped instead of panicking.
struct Writer<'a> {
    rest: &'a mut [u8],
}

impl<'a> Writer<'a> {
    fn new(out: &'a mut [u8]) -> Self {
        Writer { rest: out }
    }

    fn put<const N: usize>(&mut self, bytes: [u8; N]) {
        let rest = core::mem::take(&mut self.rest);
        if let Some((head, tail)) = rest.split_first_chunk_mut::<N>() {
            *head = bytes;
            self.rest = tail;
        }
    }

    fn u8(&mut self, v: u8) {
        self.put(v.to_le_bytes());
    }

    fn u16(&mut self, v: u16) {
        self.put(v.to_le_bytes());
    }

    fn i16(&mut self, v: i16) {
        self.put(v.to_le_bytes());
    }

    fn u32(&mut self, v: u32) {
        self.put(v.to_le_bytes());
    }

    fn u16s(&mut self, v: &[u16]) {
        v.iter().for_each(|&x| self.u16(x));
    }

    fn i16s(&mut self, v: &[i16]) {
        v.iter().for_each(|&x| self.i16(x));
    }

    fn u32s(&mut self, v: &[u32]) {
        v.iter().for_each(|&x| self.u32(x));
    }
}

/// Multi-finger command, object 0x7000 (section 2.2 / 5.4): one mode and
/// two parameters per joint, all 6 joints at once.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct MultiFingerCommand {
    /// Control mode (0x7000:01): 0 = none, else a [`ControlMode`] value.
    /// Raw so that any received byte can be represented.
    pub mode: u8,
    /// Parameter 1 per joint (0x7000:02): target position, speed, current
    /// or PWM, see [`ControlMode::param_meaning`].
    pub param1: [i16; JOINTS],
    /// Parameter 2 per joint (0x7000:03): time (ms) or speed, or unused.
    pub param2: [u16; JOINTS],
}

impl MultiFingerCommand {
    /// The control mode, if `mode` is a known one (`None` for 0 = none and
    /// for unknown values).
    pub const fn control_mode(&self) -> Option<ControlMode> {
        ControlMode::from_u8(self.mode)
    }
}

/// Single-finger command, object 0x7010 (section 2.2 / 5.4): one joint.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct SingleFingerCommand {
    /// Control mode (0x7010:01): 0 = none, else a [`ControlMode`] value.
    pub mode: u8,
    /// Target joint (0x7010:02), `finger_index_t` 0..=5; raw.
    pub joint: u8,
    /// Parameter 1 (0x7010:03).
    pub param1: i16,
    /// Parameter 2 (0x7010:04).
    pub param2: u16,
}

impl SingleFingerCommand {
    /// The control mode, if `mode` is a known one.
    pub const fn control_mode(&self) -> Option<ControlMode> {
        ControlMode::from_u8(self.mode)
    }

    /// The target joint, if `joint` is 0..=5.
    pub const fn target_joint(&self) -> Option<Joint> {
        Joint::from_u8(self.joint)
    }
}

/// The output image (RxPDO 0x1600), [`RX_LEN`] bytes.
///
/// The document does not say what the hand does when both the multi- and
/// the single-finger mode are non-zero in one cycle; senders should leave
/// the unused one at mode 0 (what [`Default`] gives).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Outputs {
    /// Multi-finger command (0x7000).
    pub multi: MultiFingerCommand,
    /// Single-finger command (0x7010).
    pub single: SingleFingerCommand,
}

impl Outputs {
    /// Image length in bytes.
    pub const LEN: usize = RX_LEN;

    /// Writes the image into `out`, which must be exactly [`RX_LEN`] bytes.
    pub fn pack(&self, out: &mut [u8]) -> Result<(), ImageError> {
        check_len(RX_LEN, out.len())?;
        self.write(&mut Writer::new(out));
        Ok(())
    }

    fn write(&self, w: &mut Writer<'_>) {
        w.u8(self.multi.mode);
        w.i16s(&self.multi.param1);
        w.u16s(&self.multi.param2);
        w.u8(self.single.mode);
        w.u8(self.single.joint);
        w.i16(self.single.param1);
        w.u16(self.single.param2);
    }

    /// Reads an image of exactly [`RX_LEN`] bytes (any content).
    pub fn unpack(bytes: &[u8]) -> Result<Self, ImageError> {
        check_len(RX_LEN, bytes.len())?;
        let mut r = Reader::new(bytes);
        let multi = MultiFingerCommand {
            mode: r.u8(),
            param1: r.i16s(),
            param2: r.u16s(),
        };
        let single = SingleFingerCommand {
            mode: r.u8(),
            joint: r.u8(),
            param1: r.i16(),
            param2: r.u16(),
        };
        Ok(Outputs { multi, single })
    }

    /// The image as an array.
    pub fn to_array(&self) -> [u8; RX_LEN] {
        let mut out = [0; RX_LEN];
        self.write(&mut Writer::new(&mut out));
        out
    }
}

/// Joint data, TxPDO 0x1A00 / object 0x6000 (section 2.3), 48 bytes.
///
/// Units follow `unit_mode` (0x8000:05): per-mille of travel / maximum
/// speed / 1000 mA, or degrees, degrees per second and mA.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct JointData {
    /// Positions (0x6000:01).
    pub position: [u16; JOINTS],
    /// Speeds (0x6000:02).
    pub speed: [i16; JOINTS],
    /// Currents (0x6000:03).
    pub current: [i16; JOINTS],
    /// Status words (0x6000:04). The document gives no bit meanings, so
    /// they stay raw.
    pub status: [u16; JOINTS],
}

impl JointData {
    /// Image length in bytes.
    pub const LEN: usize = JOINT_TX_LEN;

    fn write(&self, w: &mut Writer<'_>) {
        w.u16s(&self.position);
        w.i16s(&self.speed);
        w.i16s(&self.current);
        w.u16s(&self.status);
    }

    fn read(r: &mut Reader<'_>) -> Self {
        JointData {
            position: r.u16s(),
            speed: r.i16s(),
            current: r.i16s(),
            status: r.u16s(),
        }
    }

    /// Writes the image into `out`, exactly [`JOINT_TX_LEN`] bytes.
    pub fn pack(&self, out: &mut [u8]) -> Result<(), ImageError> {
        check_len(JOINT_TX_LEN, out.len())?;
        self.write(&mut Writer::new(out));
        Ok(())
    }

    /// Reads an image of exactly [`JOINT_TX_LEN`] bytes.
    pub fn unpack(bytes: &[u8]) -> Result<Self, ImageError> {
        check_len(JOINT_TX_LEN, bytes.len())?;
        Ok(Self::read(&mut Reader::new(bytes)))
    }
}

/// Tactile data, TxPDO 0x1A01 / object 0x6010 (section 2.4), 60 bytes.
///
/// Arrays are in [`FINGERTIP_NAMES`](crate::FINGERTIP_NAMES) order (thumb,
/// index, middle, ring, pinky; assumed, see ambiguity 3). Values are raw;
/// see [`newtons`](crate::newtons), [`direction`](crate::direction) and
/// [`TouchStatus`](crate::TouchStatus).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct TactileData {
    /// Normal force, 0.01 N (0x6010:01).
    pub normal: [u16; FINGERTIPS],
    /// Tangential force, 0.01 N (0x6010:02). Unsigned: the table and the
    /// text say UINT16, the bullet list INT16 (ambiguity 4).
    pub tangential: [u16; FINGERTIPS],
    /// Direction of the tangential force, degrees, 0xFFFF = invalid
    /// (0x6010:03); unsigned like the tangential force.
    pub direction: [u16; FINGERTIPS],
    /// Proximity, no unit given (0x6010:04).
    pub proximity: [u32; FINGERTIPS],
    /// Status words, see [`TouchStatus`](crate::TouchStatus) (0x6010:05).
    pub touch_status: [u16; FINGERTIPS],
}

impl TactileData {
    /// Image length in bytes.
    pub const LEN: usize = TACTILE_TX_LEN;

    fn write(&self, w: &mut Writer<'_>) {
        w.u16s(&self.normal);
        w.u16s(&self.tangential);
        w.u16s(&self.direction);
        w.u32s(&self.proximity);
        w.u16s(&self.touch_status);
    }

    fn read(r: &mut Reader<'_>) -> Self {
        TactileData {
            normal: r.u16s(),
            tangential: r.u16s(),
            direction: r.u16s(),
            proximity: r.u32s(),
            touch_status: r.u16s(),
        }
    }

    /// Writes the image into `out`, exactly [`TACTILE_TX_LEN`] bytes.
    pub fn pack(&self, out: &mut [u8]) -> Result<(), ImageError> {
        check_len(TACTILE_TX_LEN, out.len())?;
        self.write(&mut Writer::new(out));
        Ok(())
    }

    /// Reads an image of exactly [`TACTILE_TX_LEN`] bytes.
    pub fn unpack(bytes: &[u8]) -> Result<Self, ImageError> {
        check_len(TACTILE_TX_LEN, bytes.len())?;
        Ok(Self::read(&mut Reader::new(bytes)))
    }
}

/// The input image (SM3), laid out per an assignment of 0x1C13.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Inputs {
    /// Joint data (0x1A00), always assigned.
    pub joints: JointData,
    /// Tactile data (0x1A01), `Some` exactly when assigned.
    pub tactile: Option<TactileData>,
}

/// Checks an SM3 assignment: 0x1A00 exactly once, 0x1A01 at most once,
/// nothing else. Gives the image length and whether tactile is assigned.
fn input_layout(assignment: &[u16]) -> Result<(usize, bool), ImageError> {
    let mut joints = false;
    let mut tactile = false;
    let mut len = 0;
    for &pdo in assignment {
        let (seen, pdo_len) = match pdo {
            obj::JOINT_TX_PDO => (&mut joints, JOINT_TX_LEN),
            obj::TACTILE_TX_PDO => (&mut tactile, TACTILE_TX_LEN),
            other => return Err(ImageError::UnknownPdo(other)),
        };
        if *seen {
            return Err(ImageError::DuplicatePdo(pdo));
        }
        *seen = true;
        len += pdo_len;
    }
    if !joints {
        return Err(ImageError::MissingPdo(obj::JOINT_TX_PDO));
    }
    Ok((len, tactile))
}

impl Inputs {
    /// Length of the input image for `assignment`, after checking it as
    /// [`Inputs::unpack`] does.
    pub fn image_len(assignment: &[u16]) -> Result<usize, ImageError> {
        input_layout(assignment).map(|(len, _)| len)
    }

    /// Reads an input image laid out per `assignment` (the PDOs of 0x1C13
    /// in order, e.g. `[0x1A00]` or `[0x1A00, 0x1A01]`; any order works).
    pub fn unpack(bytes: &[u8], assignment: &[u16]) -> Result<Self, ImageError> {
        let (len, _) = input_layout(assignment)?;
        check_len(len, bytes.len())?;
        let mut r = Reader::new(bytes);
        let mut inputs = Inputs::default();
        for &pdo in assignment {
            if pdo == obj::TACTILE_TX_PDO {
                inputs.tactile = Some(TactileData::read(&mut r));
            } else {
                inputs.joints = JointData::read(&mut r);
            }
        }
        Ok(inputs)
    }

    /// Writes an input image laid out per `assignment` into `out` (exactly
    /// [`Inputs::image_len`] bytes). If 0x1A01 is assigned but `tactile` is
    /// `None`, its block is written as zeros; tactile data that is not
    /// assigned is not written.
    pub fn pack(&self, out: &mut [u8], assignment: &[u16]) -> Result<(), ImageError> {
        let (len, _) = input_layout(assignment)?;
        check_len(len, out.len())?;
        let mut w = Writer::new(out);
        for &pdo in assignment {
            if pdo == obj::TACTILE_TX_PDO {
                self.tactile.unwrap_or_default().write(&mut w);
            } else {
                self.joints.write(&mut w);
            }
        }
        Ok(())
    }
}
