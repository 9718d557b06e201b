//! The XC330-M288-T control table and the XL330-M077-T's differences as the e-manual prints
//! them; the values of its items; wire sizes and times.

use teleop_leap_protocol::wire;
use teleop_leap_protocol::xc330::{
    self, item_at, item_containing, items_covering, Access, Area, BaudRate, HardwareError,
    OperatingMode, Range, State, Table, ITEMS, XC330_M288, XL330_M077,
};
use teleop_leap_protocol::DecodeError;

#[test]
fn items_are_ordered_disjoint_and_inside_the_table() {
    for pair in ITEMS.windows(2) {
        assert!(
            pair[0].end() <= pair[1].addr,
            "{:?} overlaps {:?}",
            pair[0],
            pair[1]
        );
    }
    for item in ITEMS {
        assert!(matches!(item.size, 1 | 2 | 4), "{item:?}");
        assert!(item.end() <= xc330::TABLE_END, "{item:?}");
        let eeprom = item.addr < xc330::RAM_START;
        assert_eq!(item.area == Area::Eeprom, eeprom, "{item:?}");
    }
    assert_eq!(ITEMS.len(), 54 + 40);
    assert_eq!(
        ITEMS.last().map(|i| (i.name, i.addr)),
        Some(("Indirect Data 20", 227))
    );
}

#[test]
fn the_items_the_hand_uses() {
    let expect = [
        (xc330::MODEL_NUMBER, 2, Access::R, Some(1240)),
        (xc330::FIRMWARE_VERSION, 1, Access::R, None),
        (xc330::ID, 1, Access::RW, Some(1)),
        (xc330::BAUD_RATE, 1, Access::RW, Some(1)),
        (xc330::RETURN_DELAY_TIME, 1, Access::RW, Some(250)),
        (xc330::OPERATING_MODE, 1, Access::RW, Some(3)),
        (xc330::CURRENT_LIMIT, 2, Access::RW, Some(2352)),
        (xc330::SHUTDOWN, 1, Access::RW, Some(52)),
        (xc330::TORQUE_ENABLE, 1, Access::RW, Some(0)),
        (xc330::STATUS_RETURN_LEVEL, 1, Access::RW, Some(2)),
        (xc330::HARDWARE_ERROR_STATUS, 1, Access::R, Some(0)),
        (xc330::POSITION_D_GAIN, 2, Access::RW, Some(500)),
        (xc330::POSITION_I_GAIN, 2, Access::RW, Some(0)),
        (xc330::POSITION_P_GAIN, 2, Access::RW, Some(1100)),
        (xc330::GOAL_CURRENT, 2, Access::RW, None),
        (xc330::GOAL_POSITION, 4, Access::RW, None),
        (xc330::PRESENT_CURRENT, 2, Access::R, None),
        (xc330::PRESENT_VELOCITY, 4, Access::R, None),
        (xc330::PRESENT_POSITION, 4, Access::R, None),
        (xc330::PRESENT_INPUT_VOLTAGE, 2, Access::R, None),
        (xc330::PRESENT_TEMPERATURE, 1, Access::R, None),
    ];
    for (addr, size, access, init) in expect {
        let item = item_at(addr).unwrap_or_else(|| panic!("no item at {addr}"));
        assert_eq!(
            (item.size, item.access, item.init),
            (size, access, init),
            "{item:?}"
        );
    }
    // The section-6 items a servo answers.
    for (addr, name) in [
        (2, "Model Information"),
        (12, "Secondary(Shadow) ID"),
        (13, "Protocol Type"),
        (24, "Moving Threshold"),
        (60, "Startup Configuration"),
        (62, "PWM Slope"),
        (147, "Backup Ready"),
        (168, "Indirect Address 1"),
        (206, "Indirect Address 20"),
        (208, "Indirect Data 1"),
    ] {
        assert_eq!(item_at(addr).map(|i| i.name), Some(name));
    }
    assert_eq!(item_at(170).and_then(|i| i.init), Some(209));
    assert_eq!(item_at(206).and_then(|i| i.init), Some(227));
    assert_eq!(
        item_at(xc330::OPERATING_MODE).map(|i| i.range),
        Some(Range::OneOf(&[0, 1, 3, 4, 5, 16]))
    );
    assert_eq!(
        item_at(xc330::GOAL_CURRENT).map(|i| (i.range, i.signed)),
        Some((Range::PlusMinus(xc330::CURRENT_LIMIT), true))
    );
    // Gaps and the middle of items.
    assert!(item_at(14).is_none() && item_at(127).is_none() && item_at(228).is_none());
    assert_eq!(item_containing(127).map(|i| i.addr), Some(126));
    assert!(item_containing(14).is_none());
}

#[test]
fn items_covering_a_range() {
    let names: Vec<_> = items_covering(xc330::STATE_ADDR, xc330::STATE_LEN)
        .iter()
        .map(|i| i.name)
        .collect();
    assert_eq!(
        names,
        ["Present Current", "Present Velocity", "Present Position"]
    );
    let names: Vec<_> = items_covering(65, 6).iter().map(|i| i.addr).collect();
    assert_eq!(names, [65, 68, 69, 70]);
    assert!(items_covering(14, 6).is_empty());
    assert!(items_covering(116, 0).is_empty());
    assert!(items_covering(300, 10).is_empty());
    assert_eq!(items_covering(0xFFFF, 0xFFFF), &[]);
    assert_eq!(items_covering(0, 0xFFFF).len(), ITEMS.len());
}

#[test]
fn xl330_m077_differences() {
    let differs: Vec<_> = XC330_M288
        .items
        .iter()
        .zip(XL330_M077.items)
        .filter(|(a, b)| a != b)
        .map(|(_, b)| (b.addr, b.init))
        .collect();
    assert_eq!(
        differs,
        [
            (0, Some(1190)),
            (10, Some(0)),
            (38, Some(1750)),
            (44, Some(1620)),
            (63, Some(53)),
            (76, Some(400)),
            (78, Some(40)),
            (80, Some(0)),
            (82, Some(400)),
            (84, Some(400)),
        ]
    );
    assert_eq!(
        XL330_M077.item_at(xc330::CURRENT_LIMIT).map(|i| i.range),
        Some(Range::Span(0, 1750))
    );
    assert_eq!(Table::for_model(1240), Some(XC330_M288));
    assert_eq!(Table::for_model(1190), Some(XL330_M077));
    assert_eq!(Table::for_model(1200), None);
    assert_eq!(xc330::model_name(1240), Some("XC330-M288-T"));
    assert_eq!(xc330::model_name(1190), Some("XL330-M077-T"));
    assert_eq!(xc330::model_name(1020), None);
}

#[test]
fn signed_items_sign_extend() {
    let current = item_at(xc330::PRESENT_CURRENT).expect("item");
    assert_eq!(current.decode(&[0xFF, 0xFF]), Ok(-1));
    let voltage = item_at(xc330::PRESENT_INPUT_VOLTAGE).expect("item");
    assert_eq!(voltage.decode(&[0xFF, 0xFF]), Ok(65535));
    assert_eq!(
        current.decode(&[0xFF]),
        Err(DecodeError::DataLength {
            what: "Present Current",
            expected: 2,
            got: 1
        })
    );
}

#[test]
fn operating_modes_and_baud_rates() {
    for value in 0..=255u8 {
        match OperatingMode::from_value(value) {
            Some(mode) => assert_eq!(mode.value(), value),
            None => assert!(![0, 1, 3, 4, 5, 16].contains(&value)),
        }
    }
    assert_eq!(
        OperatingMode::from_value(5),
        Some(OperatingMode::CurrentBasedPosition)
    );
    let rates: Vec<_> = (0..=7)
        .map(|c| BaudRate::from_code(c).map(BaudRate::bps))
        .collect();
    assert_eq!(
        rates,
        [
            Some(9600),
            Some(57_600),
            Some(115_200),
            Some(1_000_000),
            Some(2_000_000),
            Some(3_000_000),
            Some(4_000_000),
            None
        ]
    );
    for rate in BaudRate::ALL {
        assert_eq!(BaudRate::from_bps(rate.bps()), Some(rate));
        assert_eq!(BaudRate::from_code(rate.code()), Some(rate));
    }
    assert_eq!(BaudRate::from_bps(4_500_000), None);
}

#[test]
fn hardware_error_words() {
    let e = HardwareError(HardwareError::OVERLOAD | HardwareError::OVERHEATING);
    assert!(e.contains(HardwareError::OVERLOAD));
    assert!(!e.contains(HardwareError::INPUT_VOLTAGE));
    assert_eq!(e.to_string(), "overheating, overload");
    assert_eq!(HardwareError(0).to_string(), "no hardware error");
    assert_eq!(HardwareError(0x42).to_string(), "undocumented bits 0x42");
    // The XC330's default Shutdown mask: overheating, electrical shock, overload.
    assert_eq!(
        HardwareError(52).words().collect::<Vec<_>>(),
        ["overheating", "electrical shock", "overload"]
    );
}

#[test]
fn state_and_units() {
    let bytes = [0x9C, 0xFF, 0x0A, 0, 0, 0, 0x00, 0x08, 0, 0];
    let s = State::decode(&bytes).expect("10 bytes");
    assert_eq!(
        s,
        State {
            current_ma: -100,
            velocity: 10,
            position: 2048
        }
    );
    assert!((s.position_rad() - std::f64::consts::PI).abs() < 1e-12);
    assert!((s.velocity_rad_s() - 10.0 * 0.229 * std::f64::consts::TAU / 60.0).abs() < 1e-12);
    assert_eq!(s.encode(), bytes);
    assert!(matches!(
        State::decode(&bytes[..9]),
        Err(DecodeError::DataLength {
            expected: 10,
            got: 9,
            ..
        })
    ));
    assert!((xc330::RAD_PER_COUNT.to_degrees() - 0.087_890_625).abs() < 1e-12);
}

#[test]
fn wire_sizes_and_times() {
    assert_eq!(wire::byte_time_ns(4_000_000), 2500);
    assert_eq!(wire::byte_time_ns(1_000_000), 10_000);
    assert_eq!(wire::byte_time_ns(57_600), 173_612);
    assert_eq!(wire::byte_time_ns(0), u64::MAX);
    assert_eq!(wire::wire_time_ns(232, 4_000_000), 580_000);
    assert_eq!(wire::packet_len(0), 10);
    assert_eq!(wire::status_len(4), 15);
    // The LEAP Hand's cycle: Fast Sync Read of 10 bytes from 16 servos.
    assert_eq!(wire::sync_read_len(16), 30);
    assert_eq!(wire::fast_sync_reply_len(16, 10), 232);
    assert_eq!(wire::fast_sync_reply_len(3, 4), 32);
    assert_eq!(wire::sync_write_len(16, 4), 94);
    assert_eq!(wire::return_delay_us(250), 500);
    assert_eq!(wire::return_delay_us(0), 0);
}
