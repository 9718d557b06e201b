//! The ESC register map as this emulator implements it (ETG.1000.4 / Beckhoff ESC datasheet
//! section II).
//!
//! Bytes not listed by [`is_present`] do not exist: reads leave the datagram untouched, writes are
//! discarded, and neither counts in the working counter (a datagram counts if at least one of
//! its bytes hits accessible memory). That includes the DC registers 0x0900..0x09FF: this ESC has
//! no distributed clocks.

/// ESC type (u8).
pub const TYPE: u16 = 0x0000;
/// ESC revision (u8).
pub const REVISION: u16 = 0x0001;
/// ESC build (u16).
pub const BUILD: u16 = 0x0002;
/// Number of FMMUs (u8).
pub const FMMU_COUNT: u16 = 0x0004;
/// Number of SyncManagers (u8).
pub const SM_COUNT: u16 = 0x0005;
/// Process RAM size in KiB (u8).
pub const RAM_SIZE: u16 = 0x0006;
/// Port descriptor (u8).
pub const PORT_DESCRIPTOR: u16 = 0x0007;
/// ESC features supported (u16); bit 2 = DC (0 here).
pub const FEATURES: u16 = 0x0008;
/// Configured station address (u16).
pub const STATION_ADDRESS: u16 = 0x0010;
/// Configured station alias (u16), loaded from SII word 4; read-only for ECAT.
pub const STATION_ALIAS: u16 = 0x0012;
/// DL control (u32); bit 24 enables alias addressing.
pub const DL_CONTROL: u16 = 0x0100;
/// DL status (u16).
pub const DL_STATUS: u16 = 0x0110;
/// AL control (u16): requested state in bits 0..3, acknowledge in bit 4.
pub const AL_CONTROL: u16 = 0x0120;
/// AL status (u16): state in bits 0..3, error in bit 4.
pub const AL_STATUS: u16 = 0x0130;
/// AL status code (u16).
pub const AL_STATUS_CODE: u16 = 0x0134;
/// PDI control (u8) and ESC configuration (u8), from SII word 0.
pub const PDI_CONTROL: u16 = 0x0140;
/// PDI configuration (u32), from SII words 1 and 3.
pub const PDI_CONFIG: u16 = 0x0150;
/// ECAT event mask (u16).
pub const ECAT_EVENT_MASK: u16 = 0x0200;
/// Error counters (0x0300..=0x0313); writing clears.
pub const ERROR_COUNTERS: u16 = 0x0300;
/// Watchdog divider (u16), in 40 ns units minus 2.
pub const WATCHDOG_DIVIDER: u16 = 0x0400;
/// PDI watchdog time (u16).
pub const WATCHDOG_PDI: u16 = 0x0410;
/// SM (process data) watchdog time (u16), in divider units; 0 disables.
pub const WATCHDOG_SM: u16 = 0x0420;
/// SM watchdog status (u16): bit 0 = 1 while not expired.
pub const WATCHDOG_SM_STATUS: u16 = 0x0440;
/// SM watchdog counter (u8); writing clears.
pub const WATCHDOG_SM_COUNTER: u16 = 0x0442;
/// SII configuration (u8): bit 0 = EEPROM assigned to PDI.
pub const SII_CONFIG: u16 = 0x0500;
/// SII PDI access state (u8), read-only.
pub const SII_PDI_ACCESS: u16 = 0x0501;
/// SII control/status (u16).
pub const SII_CONTROL: u16 = 0x0502;
/// SII address (u32, word address).
pub const SII_ADDRESS: u16 = 0x0504;
/// SII data (4 or 8 bytes).
pub const SII_DATA: u16 = 0x0508;
/// First FMMU; FMMU n is at `FMMU0 + 16 * n`.
pub const FMMU0: u16 = 0x0600;
/// First SyncManager; SM n is at `SM0 + 8 * n`.
pub const SM0: u16 = 0x0800;
/// Start of the process RAM.
pub const RAM_START: u16 = 0x1000;

/// Number of FMMUs of this ESC.
pub const NUM_FMMUS: usize = 3;
/// Number of SyncManagers of this ESC.
pub const NUM_SMS: usize = 4;

/// SII control/status bits (register 0x0502, as a u16).
pub mod sii_control {
    /// ECAT write enable (self-clearing).
    pub const WRITE_ENABLE: u16 = 1 << 0;
    /// Read size: 0 = 4 bytes, 1 = 8 bytes (read-only).
    pub const READ_8_BYTES: u16 = 1 << 6;
    /// Addressing: 0 = 1 address byte, 1 = 2 address bytes (read-only).
    pub const TWO_ADDRESS_BYTES: u16 = 1 << 7;
    /// Read command.
    pub const READ: u16 = 1 << 8;
    /// Write command.
    pub const WRITE: u16 = 1 << 9;
    /// Reload command.
    pub const RELOAD: u16 = 1 << 10;
    /// Checksum error in the ESC configuration area.
    pub const CHECKSUM_ERROR: u16 = 1 << 11;
    /// Device information (EEPROM load) error.
    pub const DEVICE_INFO_ERROR: u16 = 1 << 12;
    /// Command error (missing acknowledge or invalid command).
    pub const COMMAND_ERROR: u16 = 1 << 13;
    /// Write command without write enable.
    pub const WRITE_ENABLE_ERROR: u16 = 1 << 14;
    /// Busy.
    pub const BUSY: u16 = 1 << 15;
}

/// True if the register byte at `addr` (< 0x1000) exists in this ESC.
pub fn is_present(addr: u16) -> bool {
    let fmmu_end = FMMU0 + 16 * NUM_FMMUS as u16;
    let sm_end = SM0 + 8 * NUM_SMS as u16;
    matches!(addr,
        0x0000..=0x000F
        | 0x0010..=0x0013
        | 0x0100..=0x0103
        | 0x0110..=0x0111
        | 0x0120..=0x0121
        | 0x0130..=0x0131
        | 0x0134..=0x0135
        | 0x0140..=0x0141
        | 0x0150..=0x0153
        | 0x0200..=0x0201
        | 0x0204..=0x0207
        | 0x0210..=0x0213
        | 0x0220..=0x0223
        | 0x0300..=0x0313
        | 0x0400..=0x0401
        | 0x0410..=0x0411
        | 0x0420..=0x0421
        | 0x0440..=0x0443
        | 0x0500..=0x050F)
        || (FMMU0..fmmu_end).contains(&addr)
        || (SM0..sm_end).contains(&addr)
}

/// Address of byte `offset` of FMMU `n`.
pub fn fmmu(n: usize, offset: u16) -> u16 {
    FMMU0 + 16 * n as u16 + offset
}

/// Address of byte `offset` of SyncManager `n` (0 start, 2 length, 4 control, 5 status,
/// 6 activate, 7 PDI control).
pub fn sm(n: usize, offset: u16) -> u16 {
    SM0 + 8 * n as u16 + offset
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn presence() {
        assert!(is_present(TYPE));
        assert!(is_present(AL_STATUS_CODE + 1));
        assert!(is_present(fmmu(2, 15)));
        assert!(!is_present(fmmu(3, 0)));
        assert!(is_present(sm(3, 7)));
        assert!(!is_present(sm(4, 0)));
        // No DC.
        assert!(!(0x0900..0x0A00).any(is_present));
        assert!(!is_present(0x0F80));
    }
}
