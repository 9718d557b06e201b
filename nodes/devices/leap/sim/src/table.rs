//! One servo's control table as its firmware keeps it: the bytes, the items of its model (the
//! protocol crate's `xc330::Table`: address, size, access, EEPROM or RAM, signedness, initial
//! value, range) and the firmware's checks of a Read or a Write (ROBOTIS e-manual, Protocol
//! 2.0, "Status Packet" error numbers; XC330-M288, control table):
//!
//! - a Read reaching beyond the table: Access Error (no data); undefined bytes inside it read
//!   as 0;
//! - a Write to an undefined address or a read-only item: Access Error; to an EEPROM item
//!   while Torque Enable is 1: Access Error; covering only part of an item: Data Length Error;
//!   a value outside the item's range: Data Range Error; a goal beyond the limit another item
//!   sets (Goal PWM/Current/Velocity beyond PWM/Current/Velocity Limit, Goal Position beyond
//!   the position limits in mode 3): Data Limit Error, or Data Range Error with
//!   [`LimitError::Range`] (the documents do not say which: `docs/devices/leap.md, "Unknown"`);
//! - a Write is checked whole before any byte changes: a refused Write changes nothing.
//!
//! Items without an initial value in the e-manual start as the firmware would have them: the
//! Goals at their limits (as after a mode change), Firmware Version as configured, the present
//! values as the control loop writes them. Indirect Data is stored, not redirected.

use teleop_leap_protocol::packet::ErrorNumber;
use teleop_leap_protocol::xc330::{self, Access, Area, Item, Range};

/// Bytes of the table.
pub const TABLE_LEN: usize = xc330::TABLE_END as usize;

/// Which error a goal beyond its limit item gets (unknown: a simulator option).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LimitError {
    /// Data Limit Error (0x06).
    Limit,
    /// Data Range Error (0x04).
    Range,
}

impl std::str::FromStr for LimitError {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "limit" => Ok(Self::Limit),
            "range" => Ok(Self::Range),
            other => Err(format!("{other:?}: use limit or range")),
        }
    }
}

/// The servo model: the XC330-M288-T of the LEAP Hand, or the Lite hand's XL330-M077-T.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Model {
    /// XC330-M288-T (model number 1240).
    Xc330M288,
    /// XL330-M077-T (model number 1190).
    Xl330M077,
}

impl std::str::FromStr for Model {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "xc330-m288" => Ok(Self::Xc330M288),
            "xl330-m077" => Ok(Self::Xl330M077),
            other => Err(format!("{other:?}: use xc330-m288 or xl330-m077")),
        }
    }
}

impl Model {
    /// Its name, as `--model` takes it.
    pub fn name(self) -> &'static str {
        match self {
            Self::Xc330M288 => "xc330-m288",
            Self::Xl330M077 => "xl330-m077",
        }
    }

    /// Its control table.
    pub fn table(self) -> xc330::Table {
        match self {
            Self::Xc330M288 => xc330::XC330_M288,
            Self::Xl330M077 => xc330::XL330_M077,
        }
    }
}

/// One servo's control table.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Table {
    bytes: [u8; TABLE_LEN],
    items: xc330::Table,
    /// Per address: the index in `items` of the item starting there ([`NONE`]: none).
    index: [u8; TABLE_LEN],
}

/// No item starts at this address.
const NONE: u8 = u8::MAX;

impl Table {
    /// Every item at its initial value for `model`, with this Firmware Version.
    pub fn new(model: Model, firmware: u8) -> Self {
        let items = model.table();
        let mut index = [NONE; TABLE_LEN];
        for (k, item) in items.items.iter().enumerate() {
            if let (Some(slot), Ok(k)) = (index.get_mut(usize::from(item.addr)), u8::try_from(k)) {
                *slot = k;
            }
        }
        let mut t = Self {
            bytes: [0; TABLE_LEN],
            items,
            index,
        };
        t.factory_reset(&[]);
        t.put(xc330::FIRMWARE_VERSION, i64::from(firmware));
        t
    }

    /// Its model's items.
    pub fn items(&self) -> xc330::Table {
        self.items
    }

    /// The item starting at `addr`.
    fn item_at(&self, addr: u16) -> Option<&'static Item> {
        let k = *self.index.get(usize::from(addr))?;
        self.items.items.get(usize::from(k))
    }

    /// The initial value of `item`.
    fn init(&self, item: &Item) -> i64 {
        match (item.init, item.range) {
            (Some(v), _) => i64::from(v),
            (None, Range::PlusMinus(limit)) => self.get(limit),
            _ => 0,
        }
    }

    /// Every RAM item back at its initial value (a reboot; EEPROM stays).
    pub fn reset_ram(&mut self) {
        for item in self.items.items.iter().filter(|i| i.area == Area::Ram) {
            let v = self.init(item);
            self.put(item.addr, v);
        }
    }

    /// Every item with an initial value back at it, but those at `keep` (Factory Reset).
    pub fn factory_reset(&mut self, keep: &[u16]) {
        for item in self.items.items.iter().filter(|i| !keep.contains(&i.addr)) {
            if item.init.is_some() || item.area == Area::Ram {
                let v = self.init(item);
                self.put(item.addr, v);
            }
        }
    }

    /// The value of the item at `addr` (sign-extended where the item is signed; 0 for an
    /// address that starts no item).
    pub fn get(&self, addr: u16) -> i64 {
        let Some(item) = self.item_at(addr) else {
            return 0;
        };
        let at = usize::from(addr);
        item.decode(&self.bytes[at..at + usize::from(item.size)])
            .map_or(0, i64::from)
    }

    /// Sets the item at `addr` to `value` (truncated to its size; nothing for an address that
    /// starts no item). The firmware's own writes: no checks.
    pub fn put(&mut self, addr: u16, value: i64) {
        let Some(item) = self.item_at(addr) else {
            return;
        };
        let at = usize::from(addr);
        let n = usize::from(item.size);
        self.bytes[at..at + n].copy_from_slice(&value.to_le_bytes()[..n]);
    }

    /// The bytes a Read of `len` bytes at `addr` returns, or its error.
    pub fn read(&self, addr: u16, len: u16) -> Result<&[u8], ErrorNumber> {
        let (start, end) = (usize::from(addr), usize::from(addr) + usize::from(len));
        if len == 0 || end > TABLE_LEN {
            return Err(ErrorNumber::Access);
        }
        Ok(&self.bytes[start..end])
    }

    /// Checks a Write of `data` at `addr` as the firmware does, without changing anything.
    pub fn check_write(
        &self,
        addr: u16,
        data: &[u8],
        limit: LimitError,
    ) -> Result<(), ErrorNumber> {
        let end = usize::from(addr) + data.len();
        if data.is_empty() || end > TABLE_LEN {
            return Err(ErrorNumber::Access);
        }
        let torque_on = self.get(xc330::TORQUE_ENABLE) != 0;
        let mut at = usize::from(addr);
        while at < end {
            let item = self.item_at(at as u16).ok_or(ErrorNumber::Access)?;
            if item.access == Access::R || (item.area == Area::Eeprom && torque_on) {
                return Err(ErrorNumber::Access);
            }
            let n = usize::from(item.size);
            if at + n > end {
                return Err(ErrorNumber::DataLength);
            }
            let off = at - usize::from(addr);
            let v = item
                .decode(&data[off..off + n])
                .map_err(|_| ErrorNumber::DataLength)?;
            self.check_value(item, i64::from(v), limit)?;
            at += n;
        }
        Ok(())
    }

    /// Writes `data` at `addr` (after [`Table::check_write`]).
    pub fn write(&mut self, addr: u16, data: &[u8]) {
        let at = usize::from(addr);
        if let Some(dst) = self.bytes.get_mut(at..at + data.len()) {
            dst.copy_from_slice(data);
        }
    }

    /// Checks one item's new value against its range (and the limit items it refers to).
    fn check_value(&self, item: &Item, v: i64, limit: LimitError) -> Result<(), ErrorNumber> {
        let beyond = match limit {
            LimitError::Limit => ErrorNumber::DataLimit,
            LimitError::Range => ErrorNumber::DataRange,
        };
        let ok = match item.range {
            Range::Any => true,
            Range::Span(lo, hi) => (i64::from(lo)..=i64::from(hi)).contains(&v),
            Range::OneOf(values) => values.iter().any(|&x| i64::from(x) == v),
            Range::PlusMinus(at) => {
                let lim = self.get(at);
                if (-lim..=lim).contains(&v) {
                    true
                } else {
                    return Err(beyond);
                }
            }
            Range::Between(lo, hi) => {
                if self.get(xc330::OPERATING_MODE) == 3 {
                    if (self.get(lo)..=self.get(hi)).contains(&v) {
                        true
                    } else {
                        return Err(beyond);
                    }
                } else {
                    let ext = i64::from(xc330::EXTENDED_POSITION);
                    (-ext..=ext).contains(&v)
                }
            }
        };
        if ok {
            Ok(())
        } else {
            Err(ErrorNumber::DataRange)
        }
    }
}
