//! SII (SubDevice Information Interface) EEPROM content, as ETG.2010 lays it out.
//!
//! | words | content |
//! |---|---|
//! | 0x00..=0x07 | ESC configuration area: PDI control (0), PDI configuration (1), SYNC impulse (2), PDI configuration 2 (3), station alias (4), CRC-8 over bytes 0..14 in word 7 |
//! | 0x08..=0x0F | vendor ID, product code, revision, serial (u32 each) |
//! | 0x14..=0x17 | bootstrap mailbox: receive offset/size, send offset/size |
//! | 0x18..=0x1B | standard mailbox: receive offset/size, send offset/size |
//! | 0x1C | mailbox protocols |
//! | 0x3E | EEPROM size in KiBit - 1 |
//! | 0x3F | version (1) |
//! | 0x40.. | categories: Strings (10), General (30), FMMU (40), SyncManager (41), end 0xFFFF |

use crate::{mailbox_protocols, EscConfig, SyncManagers};

/// Category type: strings.
pub const CAT_STRINGS: u16 = 10;
/// Category type: general.
pub const CAT_GENERAL: u16 = 30;
/// Category type: FMMU usage.
pub const CAT_FMMU: u16 = 40;
/// Category type: sync managers.
pub const CAT_SYNC_MANAGER: u16 = 41;
/// Category type: end marker.
pub const CAT_END: u16 = 0xFFFF;
/// Word address of the first category.
pub const FIRST_CATEGORY: usize = 0x40;

/// PDI control word (SII word 0): SPI slave PDI, no device emulation (the application sets the
/// AL status, not the ESC).
pub const PDI_CONTROL: u16 = 0x0005;

/// SyncManager control bytes as the SII announces them (and a MainDevice copies them to the
/// SM registers): mailbox out (ECAT writes), mailbox in (ECAT reads), outputs (buffered, ECAT
/// writes, watchdog enabled), inputs (buffered, ECAT reads). Bit 5: AL event enable.
pub const SM_CONTROL: [u8; 4] = [0x26, 0x22, 0x64, 0x20];

/// CRC-8 of the ESC configuration area: polynomial 0x07, initial value 0xFF, no reflection,
/// no final XOR.
pub fn crc8(bytes: &[u8]) -> u8 {
    let mut crc = 0xFFu8;
    for &b in bytes {
        crc ^= b;
        for _ in 0..8 {
            crc = if crc & 0x80 != 0 {
                (crc << 1) ^ 0x07
            } else {
                crc << 1
            };
        }
    }
    crc
}

/// True if word 7 holds the CRC of bytes 0..14.
pub fn checksum_ok(image: &[u8]) -> bool {
    image.len() >= 16 && image[14] == crc8(&image[..14])
}

fn put_u16(image: &mut [u8], word: usize, value: u16) {
    image[word * 2..word * 2 + 2].copy_from_slice(&value.to_le_bytes());
}

fn put_u32(image: &mut [u8], word: usize, value: u32) {
    image[word * 2..word * 2 + 4].copy_from_slice(&value.to_le_bytes());
}

fn category(out: &mut Vec<u8>, kind: u16, mut data: Vec<u8>) {
    if data.len() % 2 == 1 {
        data.push(0);
    }
    out.extend_from_slice(&kind.to_le_bytes());
    // Category data is at most a few hundred bytes: the word count fits.
    out.extend_from_slice(&((data.len() / 2) as u16).to_le_bytes());
    out.extend_from_slice(&data);
}

/// Builds the SII image for `config`, with the SyncManager category announcing the default
/// process image sizes `(outputs, inputs)`. The image is padded with 0xFF (blank EEPROM) to its
/// announced size (a power of two, at least 2 KiBit).
pub fn build_image(config: &EscConfig, image_sizes: (usize, usize)) -> Vec<u8> {
    let standard = config.sync_managers == SyncManagers::Standard;
    let mut image = vec![0u8; FIRST_CATEGORY * 2];
    put_u16(&mut image, 0, PDI_CONTROL);
    let id = config.identity;
    put_u32(&mut image, 0x08, id.vendor_id);
    put_u32(&mut image, 0x0A, id.product_code);
    put_u32(&mut image, 0x0C, id.revision);
    put_u32(&mut image, 0x0E, id.serial);
    // A device with programmed sync managers has no mailbox: words 0x14..0x1C stay 0.
    if standard {
        put_u16(&mut image, 0x14, config.bootstrap_rx_mailbox.0);
        put_u16(&mut image, 0x15, config.bootstrap_rx_mailbox.1);
        put_u16(&mut image, 0x16, config.bootstrap_tx_mailbox.0);
        put_u16(&mut image, 0x17, config.bootstrap_tx_mailbox.1);
        put_u16(&mut image, 0x18, config.rx_mailbox.0);
        put_u16(&mut image, 0x19, config.rx_mailbox.1);
        put_u16(&mut image, 0x1A, config.tx_mailbox.0);
        put_u16(&mut image, 0x1B, config.tx_mailbox.1);
        put_u16(&mut image, 0x1C, config.mailbox_protocols);
    }
    put_u16(&mut image, 0x3F, 1);
    image[14] = crc8(&image[..14]);

    // Strings: one string, the device name (truncated to 255 bytes).
    let name = config.name.as_bytes();
    let name = &name[..name.len().min(255)];
    let mut strings = vec![1u8, name.len() as u8];
    strings.extend_from_slice(name);
    category(&mut image, CAT_STRINGS, strings);

    // General (ETG.2010 table 8), 32 bytes; reserved fields stay 0 (decoders are strict).
    let protocols = if standard {
        config.mailbox_protocols
    } else {
        0
    };
    let mut general = vec![0u8; 32];
    general[2] = 1; // order string: the name (ethercrab shows it)
    general[3] = 1; // name string
    general[5] = if protocols & mailbox_protocols::COE != 0 {
        // SDO, PDO assign, PDO configuration; no SDO info, no complete access.
        0x01 | 0x04 | 0x08
    } else {
        0
    };
    general[6] = u8::from(protocols & mailbox_protocols::FOE != 0);
    general[7] = u8::from(protocols & mailbox_protocols::EOE != 0);
    // Physical ports: port 0 and 1 MII.
    general[16] = 0x11;
    category(&mut image, CAT_GENERAL, general);

    if standard {
        standard_categories(&mut image, config, image_sizes);
    }
    image.extend_from_slice(&CAT_END.to_le_bytes());
    image.extend_from_slice(&CAT_END.to_le_bytes());

    let mut kibit = 2usize;
    while kibit * 128 < image.len() {
        kibit *= 2;
    }
    image.resize(kibit * 128, 0xFF);
    put_u16(&mut image, 0x3E, (kibit - 1) as u16);
    image
}

/// The FMMU and SyncManager categories of the standard layout.
fn standard_categories(image: &mut Vec<u8>, config: &EscConfig, image_sizes: (usize, usize)) {
    // FMMU usage: outputs, inputs, mailbox state (0xFF pads to a word).
    category(image, CAT_FMMU, vec![0x01, 0x02, 0x03, 0xFF]);

    // SyncManagers: start, length, control, reserved, enable, type.
    let mut sms = Vec::with_capacity(32);
    let clamp = |n: usize| u16::try_from(n).unwrap_or(u16::MAX);
    let entries = [
        (config.rx_mailbox.0, config.rx_mailbox.1, 1u8),
        (config.tx_mailbox.0, config.tx_mailbox.1, 2),
        (config.outputs_address, clamp(image_sizes.0), 3),
        (config.inputs_address, clamp(image_sizes.1), 4),
    ];
    for (i, (start, len, kind)) in entries.into_iter().enumerate() {
        sms.extend_from_slice(&start.to_le_bytes());
        sms.extend_from_slice(&len.to_le_bytes());
        sms.extend_from_slice(&[SM_CONTROL[i], 0, 0x01, kind]);
    }
    category(image, CAT_SYNC_MANAGER, sms);
}

/// The EEPROM behind the SII interface.
#[derive(Debug, Clone)]
pub(crate) struct Eeprom {
    image: Vec<u8>,
}

impl Eeprom {
    pub(crate) fn new(image: Vec<u8>) -> Self {
        Self { image }
    }

    pub(crate) fn image(&self) -> &[u8] {
        &self.image
    }

    /// Reads `out.len()` bytes from word address `word`; beyond the end reads 0xFF.
    pub(crate) fn read(&self, word: u32, out: &mut [u8]) {
        let start = (word as usize).saturating_mul(2);
        for (i, b) in out.iter_mut().enumerate() {
            *b = self
                .image
                .get(start.saturating_add(i))
                .copied()
                .unwrap_or(0xFF);
        }
    }

    /// Writes one word; false if the address is beyond the EEPROM (no acknowledge).
    pub(crate) fn write_word(&mut self, word: u32, value: [u8; 2]) -> bool {
        let start = (word as usize).saturating_mul(2);
        match self.image.get_mut(start..start.saturating_add(2)) {
            Some(slot) => {
                slot.copy_from_slice(&value);
                true
            }
            None => false,
        }
    }

    /// Needs two address bytes (more than 16 KiBit).
    pub(crate) fn two_address_bytes(&self) -> bool {
        self.image.len() > 2048
    }

    pub(crate) fn word(&self, word: usize) -> u16 {
        let mut b = [0u8; 2];
        self.read(word as u32, &mut b);
        u16::from_le_bytes(b)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn crc_matches_the_ethercat_algorithm() {
        assert_eq!(crc8(b"123456789"), 0xFB);
        // The configuration area of a Beckhoff EL2828 dump (from ethercrab's eeprom tests):
        // bytes 0..14 = 04 01 00 00 00 00 ff 00 00 00 00 00 00 00 -> word 7 = 0x00e2.
        let el2828 = [0x04, 0x01, 0, 0, 0, 0, 0xff, 0, 0, 0, 0, 0, 0, 0];
        assert_eq!(crc8(&el2828), 0xe2);
    }

    fn categories(image: &[u8]) -> Vec<(u16, Vec<u8>)> {
        let mut out = Vec::new();
        let mut word = FIRST_CATEGORY;
        loop {
            let kind = u16::from_le_bytes([image[word * 2], image[word * 2 + 1]]);
            if kind == CAT_END {
                return out;
            }
            let len = usize::from(u16::from_le_bytes([
                image[word * 2 + 2],
                image[word * 2 + 3],
            ]));
            out.push((kind, image[word * 2 + 4..(word + 2 + len) * 2].to_vec()));
            word += 2 + len;
        }
    }

    #[test]
    fn image_layout() {
        let mut config = EscConfig::default();
        config.identity.vendor_id = 0x00BC_0000;
        config.identity.product_code = 0x0000_9252;
        config.name = "Hand".into();
        config.mailbox_protocols = mailbox_protocols::COE | mailbox_protocols::FOE;
        let image = build_image(&config, (4, 6));
        assert!(checksum_ok(&image));
        assert_eq!(&image[0x10..0x14], &0x00BC_0000u32.to_le_bytes());
        assert_eq!(&image[0x14..0x18], &0x0000_9252u32.to_le_bytes());
        assert_eq!(
            &image[0x30..0x38],
            &[0x00, 0x10, 0x80, 0, 0x80, 0x10, 0x80, 0]
        );
        assert_eq!(&image[0x38..0x3A], &[0x0C, 0]);
        let size = usize::from(u16::from_le_bytes([image[0x7C], image[0x7D]]) + 1) * 128;
        assert_eq!(size, image.len());

        let cats = categories(&image);
        let kinds: Vec<u16> = cats.iter().map(|c| c.0).collect();
        assert_eq!(
            kinds,
            [CAT_STRINGS, CAT_GENERAL, CAT_FMMU, CAT_SYNC_MANAGER]
        );
        assert_eq!(&cats[0].1[..6], &[1, 4, b'H', b'a', b'n', b'd']);
        let general = &cats[1].1;
        assert_eq!(general.len(), 32);
        assert_eq!(general[5], 0x0D);
        assert_eq!(general[6], 1);
        assert_eq!(general[11], 0, "flags must only use defined bits");
        assert_eq!(cats[2].1, [1, 2, 3, 0xFF]);
        let sm = &cats[3].1;
        assert_eq!(sm.len(), 32);
        assert_eq!(&sm[16..24], &[0x00, 0x11, 4, 0, 0x64, 0, 1, 3]);
        assert_eq!(&sm[24..32], &[0x00, 0x14, 6, 0, 0x20, 0, 1, 4]);
    }

    #[test]
    fn eeprom_reads_past_the_end_as_blank() {
        let mut e = Eeprom::new(vec![1, 2, 3, 4]);
        let mut out = [0u8; 8];
        e.read(1, &mut out);
        assert_eq!(out, [3, 4, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF]);
        assert!(e.write_word(1, [9, 9]));
        assert!(!e.write_word(2, [9, 9]));
        assert_eq!(e.word(1), 0x0909);
    }
}
