//! Configuration values: parsing for `set`, access and range checks, SDO
//! bytes and decoding.

// Helpers outside #[test] functions are test code too.
#![allow(clippy::unwrap_used)]

use teleop_revo2_protocol::{
    config_entry, decode_config_value, entry, parse_config_value, ConfigError, ConfigValue,
};

#[test]
fn parses_writable_integers() {
    assert_eq!(
        parse_config_value("led_switch", "1"),
        Ok((0x8000, 0x02, ConfigValue::U8(1)))
    );
    assert_eq!(
        parse_config_value("unit_mode", " 0 "),
        Ok((0x8000, 0x05, ConfigValue::U8(0)))
    );
    assert_eq!(
        parse_config_value("thumb_flex_pro_cur", "0x3E8"),
        Ok((0x8000, 0x0A, ConfigValue::U16(1000)))
    );
    assert_eq!(
        parse_config_value("pink_pro_cur", "65535"),
        Ok((0x8000, 0x0F, ConfigValue::U16(65535)))
    );
    assert_eq!(
        parse_config_value("turbo_param", "100, 0x200"),
        Ok((0x8000, 0x09, ConfigValue::U16x2([100, 512])))
    );
    assert_eq!(
        parse_config_value("ring_acq_param_update", "255"),
        Ok((0x8010, 10, ConfigValue::U8(255)))
    );
}

#[test]
fn write_only_entries_are_allowed() {
    assert_eq!(
        parse_config_value("pos_calibration", "1"),
        Ok((0x8000, 0x06, ConfigValue::U8(1)))
    );
    assert_eq!(
        parse_config_value("foe_file_type", "2"),
        Ok((0x8000, 0x15, ConfigValue::U8(2)))
    );
    assert_eq!(
        parse_config_value("foe_auth_code", "BRCW2025"),
        Ok((0x8000, 0x16, ConfigValue::Str("BRCW2025".into())))
    );
    assert_eq!(
        parse_config_value("thumb_calibration", "1"),
        Ok((0x8010, 1, ConfigValue::U8(1)))
    );
}

#[test]
fn refuses_read_only_and_unknown() {
    for name in [
        "ctrl_wrist_fw_version",
        "wrist_fw_version",
        "touch_vendor",
        "reserved1",
        "pink_touch_fw_version",
    ] {
        assert_eq!(
            parse_config_value(name, "1"),
            Err(ConfigError::ReadOnly(config_entry(name).unwrap().name))
        );
    }
    assert_eq!(
        parse_config_value("LED_SWITCH", "1"),
        Err(ConfigError::UnknownName("LED_SWITCH".into()))
    );
    // Process data and communication objects are not configuration.
    assert!(matches!(
        parse_config_value("mult_finger_ctrl_mode", "1"),
        Err(ConfigError::UnknownName(_))
    ));
    assert!(matches!(
        parse_config_value("vendor_id", "1"),
        Err(ConfigError::UnknownName(_))
    ));
}

#[test]
fn refuses_values_outside_the_type() {
    let out = |name: &str, text: &str| {
        matches!(
            parse_config_value(name, text),
            Err(ConfigError::OutOfRange { .. })
        )
    };
    assert!(out("led_switch", "256"));
    assert!(out("led_switch", "-1"));
    assert!(out("thumb_flex_pro_cur", "65536"));
    assert!(out("turbo_param", "1,70000"));
    // Documented enumerations.
    assert!(out("hand_type", "2"));
    assert!(out("unit_mode", "2"));
    assert!(out("foe_file_type", "0"));
    assert!(out("foe_file_type", "3"));
    let invalid = |name: &str, text: &str| {
        matches!(
            parse_config_value(name, text),
            Err(ConfigError::InvalidNumber { .. })
        )
    };
    assert!(invalid("led_switch", ""));
    assert!(invalid("led_switch", "on"));
    assert!(invalid("led_switch", "0xZZ"));
    assert!(invalid("led_switch", "1.5"));
    assert!(invalid("turbo_param", "1"));
    assert!(invalid("turbo_param", "1,2,3"));
    assert!(invalid(
        "led_switch",
        "99999999999999999999999999999999999999999"
    ));
}

#[test]
fn strings() {
    assert_eq!(
        parse_config_value("ctrl_sn", "SN-0123456789ABCDE"),
        Ok((0x8000, 0x12, ConfigValue::Str("SN-0123456789ABCDE".into())))
    );
    assert_eq!(
        parse_config_value("ctrl_sn", "SN-0123456789ABCDEF"),
        Err(ConfigError::StringTooLong {
            name: "ctrl_sn",
            max: 18,
            got: 19
        })
    );
    assert_eq!(
        parse_config_value("wrist_sn", "bad\u{e9}"),
        Err(ConfigError::InvalidCharacter {
            name: "wrist_sn",
            ch: '\u{e9}'
        })
    );
    assert!(matches!(
        parse_config_value("foe_auth_code", "BRCW20251"),
        Err(ConfigError::StringTooLong { max: 8, .. })
    ));
}

#[test]
fn bytes_and_expedited() {
    assert_eq!(ConfigValue::U8(7).to_bytes(), [7]);
    assert_eq!(ConfigValue::U16(0x0102).to_bytes(), [2, 1]);
    assert_eq!(
        ConfigValue::U16x2([0x0102, 0x0304]).to_bytes(),
        [2, 1, 4, 3]
    );
    assert_eq!(ConfigValue::U32(0x0102_0304).to_bytes(), [4, 3, 2, 1]);
    assert_eq!(ConfigValue::Str("AB".into()).to_bytes(), b"AB");
    assert_eq!(
        ConfigValue::Str("AB".into()).to_bytes_padded(4),
        [b'A', b'B', 0, 0]
    );
    assert_eq!(ConfigValue::U8(1).to_bytes_padded(4), [1]);
    assert!(ConfigValue::U8(1).fits_expedited());
    assert!(ConfigValue::U16(1).fits_expedited());
    assert!(ConfigValue::U16x2([1, 2]).fits_expedited());
    assert!(!ConfigValue::Str("A".into()).fits_expedited());
    assert!(!ConfigValue::Str("BRCW2025".into()).fits_expedited());
    for (text, value) in [
        ("5", ConfigValue::U8(5)),
        ("1,2", ConfigValue::U16x2([1, 2])),
        ("x", ConfigValue::Str("x".into())),
        ("0x00BC0000", ConfigValue::U32(0x00BC_0000)),
    ] {
        assert_eq!(value.to_string(), text);
    }
}

#[test]
fn decoding() {
    let e = |index, sub| entry(index, sub).unwrap();
    assert_eq!(
        decode_config_value(e(0x8000, 0x01), &[1]),
        Ok(ConfigValue::U8(1))
    );
    assert_eq!(
        decode_config_value(e(0x8000, 0x0A), &[0xE8, 0x03]),
        Ok(ConfigValue::U16(1000))
    );
    assert_eq!(
        decode_config_value(e(0x8000, 0x09), &[1, 0, 2, 0]),
        Ok(ConfigValue::U16x2([1, 2]))
    );
    assert_eq!(
        decode_config_value(e(0x1018, 1), &[0, 0, 0xBC, 0]),
        Ok(ConfigValue::U32(0x00BC_0000))
    );
    assert_eq!(
        decode_config_value(e(0x8000, 0x0A), &[1]),
        Err(ConfigError::WrongLength {
            name: "thumb_flex_pro_cur",
            expected: 2,
            got: 1
        })
    );
    let version = e(0x8000, 0x11);
    let mut raw = [0u8; 20];
    raw[..5].copy_from_slice(b"1.2.3");
    assert_eq!(
        decode_config_value(version, &raw),
        Ok(ConfigValue::Str("1.2.3".into()))
    );
    assert_eq!(
        decode_config_value(version, b"1.2.3   "),
        Ok(ConfigValue::Str("1.2.3".into()))
    );
    // After the terminator anything goes.
    assert_eq!(
        decode_config_value(version, b"1.2.3\0\xFF\xFE"),
        Ok(ConfigValue::Str("1.2.3".into()))
    );
    assert_eq!(
        decode_config_value(version, b""),
        Ok(ConfigValue::Str(String::new()))
    );
    assert_eq!(
        decode_config_value(version, b"1.\xFF"),
        Err(ConfigError::InvalidUtf8 {
            name: "ctrl_wrist_fw_version"
        })
    );
    assert_eq!(
        decode_config_value(e(0x6000, 1), &[0; 12]),
        Err(ConfigError::Unsupported {
            index: 0x6000,
            sub: 1
        })
    );
}

#[test]
fn parse_then_decode_round_trips() {
    for (name, text) in [
        ("hand_type", "1"),
        ("turbo_param", "300,400"),
        ("mid_pro_cur", "750"),
        ("wrist_sn", "WR-2025-0001"),
    ] {
        let (index, sub, value) = parse_config_value(name, text).unwrap();
        let e = entry(index, sub).unwrap();
        assert_eq!(decode_config_value(e, &value.to_bytes()), Ok(value.clone()));
        assert_eq!(
            decode_config_value(e, &value.to_bytes_padded(e.byte_len())),
            Ok(value)
        );
    }
}
