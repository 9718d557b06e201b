//! FoE firmware: boards, header, file names.

// Helpers outside #[test] functions are test code too.
#![allow(clippy::unwrap_used)]

use teleop_revo2_protocol::{
    check_file_name, check_firmware, parse_file_name, Board, ConfigValue, FirmwareError,
    FirmwareHeader, VersionByteOrder, FOE_AUTH_CODE, FOE_FILE_TYPE, HEADER_LEN,
};

#[test]
fn boards() {
    assert_eq!(Board::Wrist.auth_code(), "BRCW2025");
    assert_eq!(Board::Control.auth_code(), "BRCC2025");
    assert_eq!(Board::Wrist.magic(), b"BRCW2025");
    assert_eq!(Board::Control.magic(), b"BRCC2025");
    assert_eq!(Board::Wrist.foe_file_type(), 1);
    assert_eq!(Board::Control.foe_file_type(), 2);
    assert_eq!(Board::from_foe_file_type(1), Some(Board::Wrist));
    assert_eq!(Board::from_foe_file_type(2), Some(Board::Control));
    assert_eq!(Board::from_foe_file_type(0), None);
    assert_eq!(Board::from_magic(b"BRCC2025"), Some(Board::Control));
    assert_eq!(Board::from_magic(b"brcc2025"), None);
    assert_eq!(FOE_FILE_TYPE, (0x8000, 0x15));
    assert_eq!(FOE_AUTH_CODE, (0x8000, 0x16));
    assert_eq!(
        Board::Wrist.foe_prelude(),
        [
            (0x8000, 0x15, ConfigValue::U8(1)),
            (0x8000, 0x16, ConfigValue::Str("BRCW2025".into())),
        ]
    );
}

#[test]
fn header_known_answer() {
    let header = FirmwareHeader::new(Board::Wrist, (1, 2, 3));
    let le = *b"BRCW2025\x03\x02\x01\x00\x00\x00\x00\x00";
    let be = *b"BRCW2025\x00\x01\x02\x03\x00\x00\x00\x00";
    assert_eq!(header.to_bytes(), le);
    assert_eq!(header.to_bytes_with(VersionByteOrder::BigEndian), be);
    assert_eq!(FirmwareHeader::parse(&le), Ok(header));
    assert_eq!(
        FirmwareHeader::parse_with(&be, VersionByteOrder::BigEndian),
        Ok(header)
    );
    // The image after the header is ignored.
    let mut file = le.to_vec();
    file.extend_from_slice(&[0xAA; 100]);
    assert_eq!(FirmwareHeader::parse(&file), Ok(header));
    let control = FirmwareHeader::new(Board::Control, (0, 0, 1));
    assert_eq!(FirmwareHeader::parse(&control.to_bytes()), Ok(control));
}

#[test]
fn header_errors() {
    let good = FirmwareHeader::new(Board::Control, (2, 0, 7)).to_bytes();
    for len in [0, 1, 8, HEADER_LEN - 1] {
        assert_eq!(
            FirmwareHeader::parse(&good[..len]),
            Err(FirmwareError::TooShort { got: len })
        );
    }
    let mut magic = good;
    magic[..8].copy_from_slice(b"BRCX2025");
    assert_eq!(
        FirmwareHeader::parse(&magic),
        Err(FirmwareError::UnknownMagic(*b"BRCX2025"))
    );
    let mut lower = good;
    lower[..8].copy_from_slice(b"brcc2025");
    assert!(matches!(
        FirmwareHeader::parse(&lower),
        Err(FirmwareError::UnknownMagic(_))
    ));
    let mut high = good;
    high[11] = 0x01;
    assert_eq!(
        FirmwareHeader::parse(&high),
        Err(FirmwareError::ReservedVersionByte(0x01))
    );
    // The same file read big-endian has patch 7 in the high byte.
    assert_eq!(
        FirmwareHeader::parse_with(&good, VersionByteOrder::BigEndian),
        Err(FirmwareError::ReservedVersionByte(7))
    );
    let mut reserved = good;
    reserved[15] = 0x80;
    assert_eq!(
        FirmwareHeader::parse(&reserved),
        Err(FirmwareError::ReservedField([0, 0, 0, 0x80]))
    );
    let header = FirmwareHeader::parse(&good).unwrap();
    assert_eq!(header.expect_board(Board::Control), Ok(header));
    assert_eq!(
        header.expect_board(Board::Wrist),
        Err(FirmwareError::WrongBoard {
            expected: Board::Wrist,
            found: Board::Control
        })
    );
}

#[test]
fn file_names_good() {
    assert_eq!(
        check_file_name("Revo2EC_0.0.1_2506231346.bin", Board::Wrist),
        Ok((0, 0, 1))
    );
    assert_eq!(
        check_file_name("Revo2_V1.2.3_2506231346.bin", Board::Control),
        Ok((1, 2, 3))
    );
    assert_eq!(
        check_file_name("Revo2_V10.255.0_202506231346.bin", Board::Control),
        Ok((10, 255, 0))
    );
    assert_eq!(
        parse_file_name("Revo2EC_1.0.0_2506231346.bin"),
        Ok((Board::Wrist, (1, 0, 0)))
    );
}

#[test]
fn file_names_wrong_board() {
    assert_eq!(
        check_file_name("Revo2_V1.2.3_2506231346.bin", Board::Wrist),
        Err(FirmwareError::WrongBoard {
            expected: Board::Wrist,
            found: Board::Control
        })
    );
    assert_eq!(
        check_file_name("Revo2EC_1.2.3_2506231346.bin", Board::Control),
        Err(FirmwareError::WrongBoard {
            expected: Board::Control,
            found: Board::Wrist
        })
    );
}

#[test]
fn file_names_bad() {
    for name in [
        "revo2ec_0.0.1_2506231346.bin",  // case
        "Revo2EC_0.0.1_2506231346.BIN",  // case of the extension
        "Revo2_v1.2.3_2506231346.bin",   // lower-case v
        "Revo2EC_V0.0.1_2506231346.bin", // V on the wrist name
        "Revo2_1.2.3_2506231346.bin",    // no V on the control name
        "Revo2EC_0.0.1_2506231346",      // truncated
        "Revo2EC_0.0.1_250623134.bin",   // 9 digits
        "Revo2EC_0.0.1_25062313460.bin", // 11 digits
        "Revo2EC_0.0.1_2506231346a.bin",
        "Revo2EC_0.0_2506231346.bin",
        "Revo2EC_0.0.1.2_2506231346.bin",
        "Revo2EC_0.0.256_2506231346.bin",
        "Revo2EC_0.0.0001_2506231346.bin",
        "Revo2EC_0..1_2506231346.bin",
        "Revo2EC_0.0.+1_2506231346.bin",
        "Revo2EC_0.0.1-2506231346.bin",
        "Revo2EC_",
        "",
        "/tmp/Revo2EC_0.0.1_2506231346.bin",
    ] {
        assert!(
            matches!(
                check_file_name(name, Board::Wrist),
                Err(FirmwareError::BadFileName { .. })
            ),
            "{name}"
        );
    }
}

#[test]
fn whole_file_check() {
    let name = "Revo2EC_1.2.3_2506231346.bin";
    let mut file = FirmwareHeader::new(Board::Wrist, (1, 2, 3))
        .to_bytes()
        .to_vec();
    file.extend_from_slice(&[0x55; 32]);
    let order = VersionByteOrder::LittleEndian;
    assert_eq!(
        check_firmware(name, &file, Board::Wrist, order),
        Ok(FirmwareHeader::new(Board::Wrist, (1, 2, 3)))
    );
    assert_eq!(
        check_firmware("Revo2EC_1.2.4_2506231346.bin", &file, Board::Wrist, order),
        Err(FirmwareError::VersionMismatch {
            name: (1, 2, 4),
            header: (1, 2, 3)
        })
    );
    let control = FirmwareHeader::new(Board::Control, (1, 2, 3)).to_bytes();
    assert_eq!(
        check_firmware(name, &control, Board::Wrist, order),
        Err(FirmwareError::WrongBoard {
            expected: Board::Wrist,
            found: Board::Control
        })
    );
    assert_eq!(
        check_firmware(name, &file[..10], Board::Wrist, order),
        Err(FirmwareError::TooShort { got: 10 })
    );
}
