//! Motor-board firmware images: Intel HEX text checked against the PIC18F bootloader's address
//! rules and cut into the 32-byte rows it programs (docs/devices/shadow.md, "Flashing").
//!
//! Records `:LLAAAATT<data>CC`: the byte sum including the checksum is 0 mod 256; types 00 data,
//! 01 end of file, 02 extended segment address (x16), 04 extended linear address (upper 16
//! bits); 03 and 05 (start addresses) are ignored. PIC18 addresses are byte addresses.
//!
//! Rules (the shipped flasher has none; these follow the bootloader): configuration words
//! (0x300000 and up: at or above 0x7FFF) are dropped, as the flasher drops them; data below
//! [`APP_START`] would overwrite the bootloader and data from [`APP_END`] is never erased, so
//! both are refused with the line that holds them. The image spans the lowest to the highest
//! address, gaps filled with 0xFF, cut into 32-byte rows from a 32-aligned start, the last row
//! padded with 0xFF.

use std::collections::BTreeMap;

use crate::can::{APP_END, APP_START, ROW};

/// Addresses from here on are configuration words, dropped.
pub const CONFIG_FROM: u32 = 0x7FFF;

/// Why a HEX file was refused: the line (1-based) and what is wrong there.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum HexError {
    /// A line that is not a record.
    #[error("line {line}: {what}")]
    Syntax {
        /// The line.
        line: usize,
        /// What is wrong.
        what: String,
    },
    /// A record whose checksum does not match.
    #[error("line {line}: checksum {found:#04x}, the record sums to {expected:#04x}")]
    Checksum {
        /// The line.
        line: usize,
        /// The checksum in the file.
        found: u8,
        /// The checksum the record's bytes need.
        expected: u8,
    },
    /// Data in the bootloader (below 0x04C0) or past the erased range (0x7DC0 and up).
    #[error(
        "line {line}: data at {address:#06x} is outside the application area 0x04C0..0x7DC0 \
         ({why})"
    )]
    Outside {
        /// The line.
        line: usize,
        /// The first address outside.
        address: u32,
        /// Why it matters.
        why: &'static str,
    },
    /// No end-of-file record.
    #[error("no end-of-file record (the file is cut short?)")]
    NoEnd,
    /// No data in the application area.
    #[error("no data for the application area")]
    Empty,
}

/// One row the bootloader programs: ADDRESS `address`, then four DATA messages.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Row {
    /// The row's first address (a multiple of 32).
    pub address: u32,
    /// Its 32 bytes.
    pub bytes: [u8; ROW],
}

/// A firmware image ready to flash.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Image {
    /// Rows in address order.
    pub rows: Vec<Row>,
    /// Data bytes the file had in the application area.
    pub data_bytes: usize,
    /// Configuration bytes dropped.
    pub dropped_config_bytes: usize,
}

impl Image {
    /// The 8 bytes at `address` as the image has them (0xFF outside it): what a READ there
    /// must return after flashing.
    pub fn bytes_at(&self, address: u32) -> [u8; 8] {
        let mut out = [0xFF; 8];
        for (k, b) in out.iter_mut().enumerate() {
            let a = address + k as u32;
            let row = self
                .rows
                .binary_search_by_key(&(a / ROW as u32 * ROW as u32), |r| r.address);
            if let Ok(i) = row {
                *b = self.rows[i].bytes[(a % ROW as u32) as usize];
            }
        }
        out
    }
}

fn hex_byte(text: &[u8], line: usize) -> Result<u8, HexError> {
    let s = std::str::from_utf8(text).map_err(|_| HexError::Syntax {
        line,
        what: "not ASCII hex".into(),
    })?;
    u8::from_str_radix(s, 16).map_err(|_| HexError::Syntax {
        line,
        what: format!("{s:?} is not a hex byte"),
    })
}

/// Parses Intel HEX `text` into an image (any text: a value or an error naming the line).
pub fn parse(text: &str) -> Result<Image, HexError> {
    let mut data: BTreeMap<u32, (u8, usize)> = BTreeMap::new();
    let mut base: u32 = 0;
    let mut dropped = 0usize;
    let mut ended = false;
    for (i, raw) in text.lines().enumerate() {
        let line = i + 1;
        let rec = raw.trim();
        if rec.is_empty() || ended {
            continue;
        }
        let Some(hex) = rec.strip_prefix(':') else {
            return Err(HexError::Syntax {
                line,
                what: "a record starts with ':'".into(),
            });
        };
        let hex = hex.as_bytes();
        if hex.len() % 2 != 0 || hex.len() < 10 {
            return Err(HexError::Syntax {
                line,
                what: format!("{} hex digits: too short or odd", hex.len()),
            });
        }
        let bytes = hex
            .chunks(2)
            .map(|c| hex_byte(c, line))
            .collect::<Result<Vec<u8>, HexError>>()?;
        let len = usize::from(bytes[0]);
        if bytes.len() != len + 5 {
            return Err(HexError::Syntax {
                line,
                what: format!("length {len} but {} data bytes", bytes.len() - 5),
            });
        }
        let sum = bytes[..bytes.len() - 1]
            .iter()
            .fold(0u8, |s, b| s.wrapping_add(*b));
        let found = bytes[bytes.len() - 1];
        let expected = sum.wrapping_neg();
        if found != expected {
            return Err(HexError::Checksum {
                line,
                found,
                expected,
            });
        }
        let offset = u32::from(u16::from_be_bytes([bytes[1], bytes[2]]));
        let payload = &bytes[4..4 + len];
        match bytes[3] {
            0x00 => {
                for (k, b) in payload.iter().enumerate() {
                    let address = base.wrapping_add(offset).wrapping_add(k as u32);
                    if address >= CONFIG_FROM {
                        dropped += 1;
                    } else if address < APP_START {
                        return Err(HexError::Outside {
                            line,
                            address,
                            why: "it would overwrite the bootloader",
                        });
                    } else if address >= APP_END {
                        return Err(HexError::Outside {
                            line,
                            address,
                            why: "the bootloader never erases it",
                        });
                    } else {
                        data.insert(address, (*b, line));
                    }
                }
            }
            0x01 => ended = true,
            0x02 | 0x04 if len != 2 => {
                return Err(HexError::Syntax {
                    line,
                    what: format!("address record with {len} data bytes, expected 2"),
                })
            }
            0x02 => base = u32::from(u16::from_be_bytes([payload[0], payload[1]])) << 4,
            0x04 => base = u32::from(u16::from_be_bytes([payload[0], payload[1]])) << 16,
            0x03 | 0x05 => {}
            t => {
                return Err(HexError::Syntax {
                    line,
                    what: format!("record type {t:#04x} is not Intel HEX"),
                })
            }
        }
    }
    if !ended {
        return Err(HexError::NoEnd);
    }
    let (Some((&low, _)), Some((&high, _))) = (data.first_key_value(), data.last_key_value())
    else {
        return Err(HexError::Empty);
    };
    let start = low / ROW as u32 * ROW as u32;
    let mut rows = Vec::new();
    let mut address = start;
    while address <= high {
        let mut bytes = [0xFF; ROW];
        for (k, b) in bytes.iter_mut().enumerate() {
            if let Some((v, _)) = data.get(&(address + k as u32)) {
                *b = *v;
            }
        }
        rows.push(Row { address, bytes });
        address += ROW as u32;
    }
    Ok(Image {
        rows,
        data_bytes: data.len(),
        dropped_config_bytes: dropped,
    })
}

/// Writes `bytes` at `address` as Intel HEX (16-byte data records, extended linear address
/// records where needed, end of file): for tests and for generating images.
pub fn write(address: u32, bytes: &[u8]) -> String {
    fn record(out: &mut String, kind: u8, offset: u16, data: &[u8]) {
        let mut all = vec![data.len() as u8, (offset >> 8) as u8, offset as u8, kind];
        all.extend_from_slice(data);
        let sum = all
            .iter()
            .fold(0u8, |s, b| s.wrapping_add(*b))
            .wrapping_neg();
        out.push(':');
        for b in all.iter().chain(std::iter::once(&sum)) {
            out.push_str(&format!("{b:02X}"));
        }
        out.push('\n');
    }
    let mut out = String::new();
    let mut upper = None;
    for (k, chunk) in bytes.chunks(16).enumerate() {
        let a = address + 16 * k as u32;
        if upper != Some(a >> 16) {
            upper = Some(a >> 16);
            record(&mut out, 0x04, 0, &((a >> 16) as u16).to_be_bytes());
        }
        record(&mut out, 0x00, a as u16, chunk);
    }
    record(&mut out, 0x01, 0, &[]);
    out
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use super::*;
    use proptest::prelude::*;

    #[test]
    fn records_computed_by_hand() {
        // 4 bytes at 0x04C0: 04 04C0 00 01020304, sum 0x04+0x04+0xC0+0x00+1+2+3+4 = 0xD2,
        // checksum 0x2E. Then a config byte at 0x300001 (dropped) and the end record.
        let text =
            ":020000040000FA\n:0404C000010203042E\n:020000040030CA\n:01000100FFFF\n:00000001FF\n";
        let image = parse(text).unwrap();
        assert_eq!(image.data_bytes, 4);
        assert_eq!(image.dropped_config_bytes, 1);
        assert_eq!(image.rows.len(), 1);
        assert_eq!(image.rows[0].address, 0x04C0);
        assert_eq!(&image.rows[0].bytes[..5], &[1, 2, 3, 4, 0xFF]);
        assert_eq!(image.bytes_at(0x04C0), [1, 2, 3, 4, 0xFF, 0xFF, 0xFF, 0xFF]);
    }

    #[test]
    fn refusals_name_the_line() {
        let bad_sum = ":020000040000FA\n:0404C000010203042F\n:00000001FF\n";
        assert_eq!(
            parse(bad_sum).unwrap_err(),
            HexError::Checksum {
                line: 2,
                found: 0x2F,
                expected: 0x2E
            }
        );
        let boot = write(0x0400, &[0; 4]);
        let e = parse(&boot).unwrap_err();
        assert!(
            matches!(
                e,
                HexError::Outside {
                    line: 2,
                    address: 0x400,
                    ..
                }
            ),
            "{e}"
        );
        assert!(e.to_string().contains("bootloader"));
        let high = write(0x7DC0, &[0; 4]);
        assert!(matches!(
            parse(&high),
            Err(HexError::Outside {
                address: 0x7DC0,
                ..
            })
        ));
        assert_eq!(parse(":0404C000010203042E\n"), Err(HexError::NoEnd));
        assert_eq!(parse(":00000001FF\n"), Err(HexError::Empty));
        assert!(matches!(
            parse("hello\n"),
            Err(HexError::Syntax { line: 1, .. })
        ));
    }

    #[test]
    fn images_round_trip_through_write_in_padded_rows() {
        let bytes: Vec<u8> = (0..100u8).collect();
        let image = parse(&write(0x0500, &bytes)).unwrap();
        assert_eq!(image.data_bytes, 100);
        // 0x0500..0x0564: rows 0x0500, 0x0520, 0x0540, 0x0560 (the last padded).
        assert_eq!(image.rows.len(), 4);
        assert_eq!(image.rows[3].bytes[4], 0xFF);
        assert_eq!(
            image.bytes_at(0x0560),
            [96, 97, 98, 99, 0xFF, 0xFF, 0xFF, 0xFF]
        );
    }

    proptest! {
        #[test]
        fn any_text_gives_an_image_or_an_error(text in ".{0,400}") {
            let _ = parse(&text);
        }

        #[test]
        fn written_images_parse_back(start in 0x04C0u32..0x7000, len in 1usize..600, seed in any::<u8>()) {
            let bytes: Vec<u8> = (0..len).map(|k| (k as u8).wrapping_mul(31).wrapping_add(seed)).collect();
            let image = parse(&write(start, &bytes)).unwrap();
            prop_assert_eq!(image.data_bytes, len);
            for k in (0..len).step_by(8) {
                let got = image.bytes_at(start + k as u32);
                for (j, b) in got.iter().enumerate() {
                    let want = bytes.get(k + j).copied().unwrap_or(0xFF);
                    prop_assert_eq!(*b, want);
                }
            }
        }
    }
}
