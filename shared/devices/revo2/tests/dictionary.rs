//! Object dictionary: facts from the document, internal consistency,
//! mapping encoding.

// Helpers outside #[test] functions are test code too.
#![allow(clippy::unwrap_used)]

use std::collections::HashSet;

use teleop_revo2_protocol::{
    config_entries, config_entry, entry, image_len, mapping_entries, obj, object_entries, Access,
    DataType, DefaultValue, Joint, MappingEntry, PdoDirection, DEVICE_NAME, DICTIONARY,
    FINGERTIP_NAMES, JOINT_NAMES, PRODUCT_CODE, REVISION, VENDOR_ID,
};

#[test]
fn identity() {
    assert_eq!(VENDOR_ID, 0x00BC_0000);
    assert_eq!(PRODUCT_CODE, 0x0000_9252);
    assert_eq!(REVISION, 1);
    let sub = |s| entry(0x1018, s).unwrap().default;
    assert_eq!(sub(0), Some(DefaultValue::Unsigned(4)));
    assert_eq!(sub(1), Some(DefaultValue::Unsigned(VENDOR_ID)));
    assert_eq!(sub(2), Some(DefaultValue::Unsigned(PRODUCT_CODE)));
    assert_eq!(sub(3), Some(DefaultValue::Unsigned(REVISION)));
    assert_eq!(entry(0x1018, 4).unwrap().data_type, DataType::Uint32);
    let name = entry(0x1008, 0).unwrap();
    assert_eq!(name.default, Some(DefaultValue::Str("BrainCo-Revo2Slave")));
    assert_eq!(name.byte_len(), DEVICE_NAME.len());
    for index in [0x1000, 0x1009, 0x100A] {
        assert!(entry(index, 0).is_some(), "0x{index:04X}");
    }
    assert_eq!(entry(0x1009, 0).unwrap().data_type, DataType::VisibleString);
}

#[test]
fn joints_and_fingertips() {
    assert_eq!(
        JOINT_NAMES,
        [
            "thumb_flex",
            "thumb_abduct",
            "index",
            "middle",
            "ring",
            "pinky"
        ]
    );
    assert_eq!(
        FINGERTIP_NAMES,
        ["thumb", "index", "middle", "ring", "pinky"]
    );
    for (i, joint) in Joint::ALL.into_iter().enumerate() {
        assert_eq!(joint.index(), i);
        assert_eq!(Joint::from_u8(i as u8), Some(joint));
        assert_eq!(joint.name(), JOINT_NAMES[i]);
    }
    assert_eq!(Joint::from_u8(6), None);
    assert_eq!(Joint::ThumbAbduct.fingertip(), 0);
    assert_eq!(FINGERTIP_NAMES[Joint::Pinky.fingertip()], "pinky");
    assert_eq!(FINGERTIP_NAMES[Joint::Index.fingertip()], "index");
}

#[test]
fn entries_unique_and_sized_by_type() {
    let mut seen = HashSet::new();
    for e in DICTIONARY {
        assert!(
            seen.insert((e.index, e.sub)),
            "duplicate 0x{:04X}:{:02X}",
            e.index,
            e.sub
        );
        let bits = e.data_type.element_bits();
        assert!(e.bit_len > 0 && e.bit_len % bits == 0, "{}", e.name);
        assert!(!e.name.is_empty() && !e.description.is_empty());
        assert_eq!(DataType::from_code(e.data_type.code()), Some(e.data_type));
        match e.default {
            Some(DefaultValue::Str(s)) => {
                assert!(e.data_type.is_string());
                assert!(s.len() <= e.byte_len());
            }
            Some(DefaultValue::Unsigned(v)) => {
                assert!(!e.data_type.is_string());
                assert!(e.bit_len >= 32 || u64::from(v) < 1u64 << e.bit_len);
            }
            None => {}
        }
        if e.pdo == PdoDirection::Tx {
            assert_eq!(e.access, Access::Ro, "{}", e.name);
        }
    }
}

#[test]
fn data_type_codes() {
    assert_eq!(DataType::Bool.code(), 0x0001);
    assert_eq!(DataType::Int8.code(), 0x0002);
    assert_eq!(DataType::Int16.code(), 0x0003);
    assert_eq!(DataType::Int32.code(), 0x0004);
    assert_eq!(DataType::Uint8.code(), 0x0005);
    assert_eq!(DataType::Uint16.code(), 0x0006);
    assert_eq!(DataType::Uint32.code(), 0x0007);
    assert_eq!(DataType::VisibleString.code(), 0x0009);
    assert_eq!(DataType::OctetString.code(), 0x000A);
    assert_eq!(DataType::from_code(0x0100), None);
}

#[test]
fn sub_zero_counts_match() {
    let records: HashSet<u16> = DICTIONARY
        .iter()
        .filter(|e| e.sub != 0)
        .map(|e| e.index)
        .collect();
    for index in records {
        let count = entry(index, 0).unwrap();
        let highest = object_entries(index).map(|e| e.sub).max().unwrap();
        assert_eq!(
            count.default,
            Some(DefaultValue::Unsigned(u32::from(highest))),
            "0x{index:04X}"
        );
        // Sub-indices are contiguous 0..=highest.
        assert_eq!(object_entries(index).count(), usize::from(highest) + 1);
    }
}

#[test]
fn process_data_objects_match_the_document() {
    let expect: [(u16, u8, DataType, u16, PdoDirection); 16] = [
        (0x7000, 1, DataType::Uint8, 8, PdoDirection::Rx),
        (0x7000, 2, DataType::Int16, 96, PdoDirection::Rx),
        (0x7000, 3, DataType::Uint16, 96, PdoDirection::Rx),
        (0x7010, 1, DataType::Uint8, 8, PdoDirection::Rx),
        (0x7010, 2, DataType::Uint8, 8, PdoDirection::Rx),
        (0x7010, 3, DataType::Int16, 16, PdoDirection::Rx),
        (0x7010, 4, DataType::Uint16, 16, PdoDirection::Rx),
        (0x6000, 1, DataType::Uint16, 96, PdoDirection::Tx),
        (0x6000, 2, DataType::Int16, 96, PdoDirection::Tx),
        (0x6000, 3, DataType::Int16, 96, PdoDirection::Tx),
        (0x6000, 4, DataType::Uint16, 96, PdoDirection::Tx),
        (0x6010, 1, DataType::Uint16, 80, PdoDirection::Tx),
        (0x6010, 2, DataType::Uint16, 80, PdoDirection::Tx),
        (0x6010, 3, DataType::Uint16, 80, PdoDirection::Tx),
        (0x6010, 4, DataType::Uint32, 160, PdoDirection::Tx),
        (0x6010, 5, DataType::Uint16, 80, PdoDirection::Tx),
    ];
    for (index, sub, dt, bits, pdo) in expect {
        let e = entry(index, sub).unwrap();
        assert_eq!(
            (e.data_type, e.bit_len, e.pdo),
            (dt, bits, pdo),
            "{}",
            e.name
        );
    }
    let mappable = DICTIONARY
        .iter()
        .filter(|e| e.pdo != PdoDirection::None)
        .count();
    assert_eq!(mappable, expect.len());
}

#[test]
fn config_objects_match_the_document() {
    use Access::{Ro, Rw, Wo};
    use DataType::{Uint16, Uint8, VisibleString as Str};
    let c8000: [(&str, DataType, u16, Access); 22] = [
        ("hand_type", Uint8, 8, Rw),
        ("led_switch", Uint8, 8, Rw),
        ("buzzer_switch", Uint8, 8, Rw),
        ("vibrator_switch", Uint8, 8, Rw),
        ("unit_mode", Uint8, 8, Rw),
        ("pos_calibration", Uint8, 8, Wo),
        ("auto_calibration", Uint8, 8, Rw),
        ("turbo_mode", Uint8, 8, Rw),
        ("turbo_param", Uint16, 32, Rw),
        ("thumb_flex_pro_cur", Uint16, 16, Rw),
        ("thumb_aux_pro_cur", Uint16, 16, Rw),
        ("index_pro_cur", Uint16, 16, Rw),
        ("mid_pro_cur", Uint16, 16, Rw),
        ("ring_pro_cur", Uint16, 16, Rw),
        ("pink_pro_cur", Uint16, 16, Rw),
        ("thumb_aux_lock_cur", Uint16, 16, Rw),
        ("ctrl_wrist_fw_version", Str, 160, Ro),
        ("ctrl_sn", Str, 144, Rw),
        ("wrist_fw_version", Str, 160, Ro),
        ("wrist_sn", Str, 144, Rw),
        ("foe_file_type", Uint8, 8, Wo),
        ("foe_auth_code", Str, 64, Wo),
    ];
    for (i, (name, dt, bits, access)) in c8000.into_iter().enumerate() {
        let e = entry(0x8000, i as u8 + 1).unwrap();
        assert_eq!(
            (e.name, e.data_type, e.bit_len, e.access),
            (name, dt, bits, access)
        );
        assert_eq!(config_entry(name), Some(e));
    }
    let c8010: [(&str, DataType, u16, Access); 17] = [
        ("thumb_calibration", Uint8, 8, Wo),
        ("index_calibration", Uint8, 8, Wo),
        ("mid_calibration", Uint8, 8, Wo),
        ("ring_calibration", Uint8, 8, Wo),
        ("pinky_calibration", Uint8, 8, Wo),
        ("touch_vendor", Uint8, 8, Ro),
        ("thumb_acq_param_update", Uint8, 8, Wo),
        ("index_acq_param_update", Uint8, 8, Wo),
        ("mid_acq_param_update", Uint8, 8, Wo),
        ("ring_acq_param_update", Uint8, 8, Wo),
        ("prink_acq_param_update", Uint8, 8, Wo),
        ("reserved1", Uint8, 8, Ro),
        ("thumb_touch_fw_version", Str, 160, Ro),
        ("index_touch_fw_version", Str, 160, Ro),
        ("mid_touch_fw_version", Str, 160, Ro),
        ("ring_touch_fw_version", Str, 160, Ro),
        ("pink_touch_fw_version", Str, 160, Ro),
    ];
    for (i, (name, dt, bits, access)) in c8010.into_iter().enumerate() {
        let e = entry(0x8010, i as u8 + 1).unwrap();
        assert_eq!(
            (e.name, e.data_type, e.bit_len, e.access),
            (name, dt, bits, access)
        );
        assert_eq!(config_entry(name), Some(e));
    }
    assert_eq!(config_entries().count(), 22 + 17);
    // Config names are unique.
    let names: HashSet<&str> = config_entries().map(|e| e.name).collect();
    assert_eq!(names.len(), 22 + 17);
    assert_eq!(config_entry("no_such_thing"), None);
    assert_eq!(config_entry("mult_finger_ctrl_mode"), None);
}

#[test]
fn mapping_entry_encoding() {
    let m = MappingEntry::new(0x7000, 0x02, 96);
    assert_eq!(m.encode(), 0x7000_0260);
    assert_eq!(MappingEntry::decode(0x7000_0260), m);
    assert_eq!(MappingEntry::new(0x6010, 0x04, 160).encode(), 0x6010_04A0);
    assert_eq!(
        MappingEntry::decode(0xFFFF_FFFF),
        MappingEntry::new(0xFFFF, 0xFF, 0xFF)
    );
    for raw in [0u32, 1, 0x1234_5678, 0x8000_0001, u32::MAX] {
        assert_eq!(MappingEntry::decode(raw).encode(), raw);
    }
}

#[test]
fn mappings_agree_with_the_dictionary() {
    let expect_rx = [
        0x7000_0108u32,
        0x7000_0260,
        0x7000_0360,
        0x7010_0108,
        0x7010_0208,
        0x7010_0310,
        0x7010_0410,
    ];
    let rx: Vec<u32> = mapping_entries(0x1600)
        .unwrap()
        .iter()
        .map(|m| m.encode())
        .collect();
    assert_eq!(rx, expect_rx);
    for (pdo, direction) in [
        (obj::RX_PDO, PdoDirection::Rx),
        (obj::JOINT_TX_PDO, PdoDirection::Tx),
        (obj::TACTILE_TX_PDO, PdoDirection::Tx),
    ] {
        let mapping = mapping_entries(pdo).unwrap();
        assert_eq!(
            entry(pdo, 0).unwrap().default,
            Some(DefaultValue::Unsigned(mapping.len() as u32))
        );
        for (i, m) in mapping.iter().enumerate() {
            let sub = entry(pdo, i as u8 + 1).unwrap();
            assert_eq!(sub.default, Some(DefaultValue::Unsigned(m.encode())));
            assert_eq!(sub.access, Access::Ro);
            let mapped = entry(m.index, m.sub).unwrap();
            assert_eq!(mapped.bit_len, u16::from(m.bit_len), "{}", mapped.name);
            assert_eq!(mapped.pdo, direction, "{}", mapped.name);
        }
    }
    assert_eq!(mapping_entries(0x1A02), None);
    assert_eq!(mapping_entries(0x1C12), None);
}

#[test]
fn assignments() {
    let a = |index, sub| entry(index, sub).unwrap();
    assert_eq!(a(0x1C12, 0).default, Some(DefaultValue::Unsigned(1)));
    assert_eq!(a(0x1C12, 1).default, Some(DefaultValue::Unsigned(0x1600)));
    assert_eq!(a(0x1C13, 0).default, Some(DefaultValue::Unsigned(2)));
    assert_eq!(a(0x1C13, 1).default, Some(DefaultValue::Unsigned(0x1A00)));
    assert_eq!(a(0x1C13, 2).default, Some(DefaultValue::Unsigned(0x1A01)));
    for sub in 0..=2 {
        assert_eq!(a(0x1C13, sub).access, Access::Rw);
    }
    assert_eq!(image_len(&[]), Some(0));
    assert_eq!(image_len(&[0x1A00, 0x1234]), None);
    assert_eq!(image_len(&[0x1600, 0x1A00]), Some(31 + 48));
}
