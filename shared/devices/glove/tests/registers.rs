//! Register map: facts from the manual, write/read encoding, value decoding.

// Helpers outside #[test] functions are test code too.
#![allow(clippy::unwrap_used)]

use core::time::Duration;

use teleop_glove_protocol::{
    decode_values, encode_request, encode_response, read_request, reg, register_at,
    register_containing, wire_time, write_request, Access, BaudRate, Data, EncodeError, ErrorBits,
    Frame, Register, RegisterError, Request, RequestDecoder, Response, ResponseDecoder, Width,
    CALIBRATION_STEPS, MAX_FRAME, REGISTERS,
};

#[test]
fn map_matches_the_manual() {
    let expect: [(Register, u16, Width, u8, Access); 14] = [
        (reg::ID, 1000, Width::U8, 1, Access::ReadWrite),
        (reg::BAUD_RATE, 1001, Width::U8, 1, Access::ReadWrite),
        (reg::ERROR_CLEAR, 1004, Width::U8, 1, Access::ReadWrite),
        (reg::SAVE, 1005, Width::U8, 1, Access::ReadWrite),
        (reg::FACTORY_RESET, 1006, Width::U8, 1, Access::ReadWrite),
        (reg::CALIBRATION, 1009, Width::U8, 1, Access::ReadWrite),
        (reg::VOLTAGE, 1472, Width::U16, 1, Access::ReadOnly),
        (reg::POSITION_SET, 1486, Width::I16, 5, Access::ReadWrite),
        (reg::FORCE_SET, 1498, Width::I16, 5, Access::ReadWrite),
        (reg::POSITION_ACTUAL, 1546, Width::I16, 6, Access::ReadOnly),
        (reg::FORCE_ACTUAL, 1582, Width::I16, 5, Access::ReadOnly),
        (reg::CURRENT, 1594, Width::U16, 5, Access::ReadOnly),
        (reg::ERROR_CODE, 1606, Width::U8, 5, Access::ReadOnly),
        (reg::TEMPERATURE, 1618, Width::U8, 5, Access::ReadOnly),
    ];
    assert_eq!(REGISTERS.len(), expect.len());
    for (r, (e, address, width, count, access)) in REGISTERS.iter().zip(expect) {
        assert_eq!(*r, e);
        assert_eq!(
            (r.address, r.width, r.count, r.access),
            (address, width, count, access),
            "{}",
            r.name
        );
        assert!(!r.meaning.is_empty());
    }
    // Ascending and non-overlapping.
    for pair in REGISTERS.windows(2) {
        assert!(pair[0].end() <= pair[1].address, "{}", pair[0].name);
    }
    assert_eq!(reg::ID.default, Some(1));
    const { assert!(reg::ID.savable && reg::BAUD_RATE.savable) };
    const { assert!(!reg::ERROR_CLEAR.savable && !reg::SAVE.savable) };
    assert_eq!((reg::ID.min, reg::ID.max), (1, 254));
    assert_eq!(reg::POSITION_SET.special, Some(-1));
    assert_eq!((reg::FORCE_SET.min, reg::FORCE_SET.max), (-1000, 1000));
    assert_eq!(reg::CURRENT.unit, "mA");
    assert_eq!(reg::TEMPERATURE.max, 100);
    assert_eq!(reg::POSITION_ACTUAL.byte_len(), 12);
    assert_eq!(reg::POSITION_ACTUAL.end(), 1558);
    assert_eq!(reg::TEMPERATURE.end(), 1623);
}

#[test]
fn lookups() {
    assert_eq!(register_at(1000), Some(&reg::ID));
    assert_eq!(register_at(1006), Some(&reg::FACTORY_RESET));
    assert_eq!(register_at(1487), None);
    assert_eq!(register_containing(1487), Some((&reg::POSITION_SET, 1)));
    assert_eq!(register_containing(1495), Some((&reg::POSITION_SET, 9)));
    assert_eq!(register_containing(1496), None);
    // 1609 is the index finger's error code (our reading of 2.3.12).
    assert_eq!(register_containing(1609), Some((&reg::ERROR_CODE, 3)));
    assert_eq!(register_containing(1622), Some((&reg::TEMPERATURE, 4)));
    assert_eq!(register_containing(1623), None);
    assert_eq!(register_containing(0), None);
    assert_eq!(register_containing(u16::MAX), None);
}

/// Sample values for every register: min, max, special and some middle.
fn samples(r: &Register) -> Vec<Vec<i32>> {
    let n = usize::from(r.count);
    let mut out = vec![vec![r.min; n], vec![r.max; n]];
    let mut mixed: Vec<i32> = (0..n as i32).map(|i| r.min + i).collect();
    if let Some(s) = r.special {
        mixed[n / 2] = s;
    }
    out.push(mixed);
    out
}

/// Encodes `bytes` as the glove's read answer, decodes it, returns the data.
fn through_read_answer(r: &Register, bytes: &[u8]) -> Vec<u8> {
    let answer = Response::ReadRegister {
        address: r.address,
        data: Data::new(bytes).unwrap(),
    };
    let mut buf = [0u8; MAX_FRAME];
    let n = encode_response(1, &answer, &mut buf).unwrap();
    let mut d = ResponseDecoder::new(Some(1));
    d.push(&buf[..n]);
    match d.next() {
        Some(Ok(Frame {
            id: 1,
            body: Response::ReadRegister { address, data },
        })) if address == r.address => data.as_slice().to_vec(),
        other => panic!("unexpected {other:?}"),
    }
}

#[test]
fn every_register_round_trips() {
    for r in REGISTERS {
        // Read request: encodes, decodes, asks for the whole register.
        let read = read_request(r);
        assert_eq!(
            read,
            Request::ReadRegister {
                address: r.address,
                len: r.byte_len() as u8
            }
        );
        let mut buf = [0u8; MAX_FRAME];
        let n = encode_request(1, &read, &mut buf).unwrap();
        let mut d = RequestDecoder::new(Some(1));
        d.push(&buf[..n]);
        assert_eq!(d.next(), Some(Ok(Frame { id: 1, body: read })));

        for values in samples(r) {
            // The glove's answer carrying these values decodes back to them.
            let raw = match r.width {
                Width::U8 => values.iter().map(|&v| v as u8).collect::<Vec<_>>(),
                Width::I16 => values
                    .iter()
                    .flat_map(|&v| (v as i16).to_le_bytes())
                    .collect(),
                Width::U16 => values
                    .iter()
                    .flat_map(|&v| (v as u16).to_le_bytes())
                    .collect(),
            };
            let data = through_read_answer(r, &raw);
            let decoded = decode_values(r, &data).unwrap();
            assert_eq!(decoded.as_slice(), &values[..], "{}", r.name);
            assert_eq!(decoded.count, values.len());

            match r.access {
                Access::ReadOnly => assert_eq!(
                    write_request(r, &values),
                    Err(EncodeError::ReadOnly(r.name))
                ),
                Access::ReadWrite => {
                    let w = write_request(r, &values).unwrap();
                    let Request::WriteRegister { address, data } = w else {
                        panic!("not a write: {w:?}");
                    };
                    assert_eq!(address, r.address);
                    assert_eq!(data.as_slice(), &raw[..], "{}", r.name);
                    let n = encode_request(1, &w, &mut buf).unwrap();
                    let mut d = RequestDecoder::new(None);
                    d.push(&buf[..n]);
                    assert_eq!(d.next(), Some(Ok(Frame { id: 1, body: w })));
                }
            }
        }
    }
}

#[test]
fn write_refusals() {
    assert_eq!(
        write_request(&reg::ID, &[0]),
        Err(EncodeError::ValueOutOfRange {
            register: "id",
            index: 0,
            value: 0
        })
    );
    assert_eq!(
        write_request(&reg::ID, &[255]),
        Err(EncodeError::ValueOutOfRange {
            register: "id",
            index: 0,
            value: 255
        })
    );
    assert_eq!(
        write_request(&reg::BAUD_RATE, &[3]),
        Err(EncodeError::ValueOutOfRange {
            register: "baud_rate",
            index: 0,
            value: 3
        })
    );
    assert_eq!(
        write_request(&reg::POSITION_SET, &[0, 1000, -1, 1001, 0]),
        Err(EncodeError::ValueOutOfRange {
            register: "position_set",
            index: 3,
            value: 1001
        })
    );
    assert_eq!(
        write_request(&reg::POSITION_SET, &[-2, 0, 0, 0, 0]),
        Err(EncodeError::ValueOutOfRange {
            register: "position_set",
            index: 0,
            value: -2
        })
    );
    // -1 is special only for the position set-points.
    assert!(write_request(&reg::FORCE_SET, &[-1; 5]).is_ok());
    assert_eq!(
        write_request(&reg::FORCE_SET, &[0, 0, 0, 0, -1001]),
        Err(EncodeError::ValueOutOfRange {
            register: "force_set",
            index: 4,
            value: -1001
        })
    );
    assert_eq!(
        write_request(&reg::ERROR_CLEAR, &[-1]),
        Err(EncodeError::ValueOutOfRange {
            register: "error_clear",
            index: 0,
            value: -1
        })
    );
    assert_eq!(
        write_request(&reg::FORCE_SET, &[0; 4]),
        Err(EncodeError::WrongCount {
            register: "force_set",
            expected: 5,
            got: 4
        })
    );
    assert_eq!(
        write_request(&reg::ID, &[]),
        Err(EncodeError::WrongCount {
            register: "id",
            expected: 1,
            got: 0
        })
    );
    for r in [
        reg::VOLTAGE,
        reg::POSITION_ACTUAL,
        reg::FORCE_ACTUAL,
        reg::CURRENT,
        reg::ERROR_CODE,
        reg::TEMPERATURE,
    ] {
        assert_eq!(
            write_request(&r, &vec![0; usize::from(r.count)]),
            Err(EncodeError::ReadOnly(r.name))
        );
    }
}

#[test]
fn known_write_bytes() {
    // Position set-points 500, 500, -1, 0, 500 (the manual's example).
    let w = write_request(&reg::POSITION_SET, &[500, 500, -1, 0, 500]).unwrap();
    let mut buf = [0u8; MAX_FRAME];
    let n = encode_request(1, &w, &mut buf).unwrap();
    let mut expected = vec![0xEB, 0x90, 0x01, 13, 0x12, 0xCE, 0x05];
    expected.extend([0xF4, 0x01, 0xF4, 0x01, 0xFF, 0xFF, 0x00, 0x00, 0xF4, 0x01]);
    let chk = expected[2..].iter().fold(0u8, |s, b| s.wrapping_add(*b));
    expected.push(chk);
    assert_eq!(&buf[..n], &expected[..]);
}

#[test]
fn decode_values_checks_length_and_keeps_raw_values() {
    assert_eq!(
        decode_values(&reg::FORCE_ACTUAL, &[0; 9]),
        Err(RegisterError::WrongLength {
            register: "force_actual",
            expected: 10,
            got: 9
        })
    );
    assert!(decode_values(&reg::ID, &[]).is_err());
    // Out of range values are returned as read.
    let v = decode_values(&reg::TEMPERATURE, &[0, 100, 101, 255, 7]).unwrap();
    assert_eq!(v.as_slice(), &[0, 100, 101, 255, 7]);
    let v = decode_values(&reg::CURRENT, &[0xFF, 0xFF, 0, 0, 0, 0, 0, 0, 0, 0]).unwrap();
    assert_eq!(v.as_slice()[0], 65535);
    let v = decode_values(&reg::POSITION_ACTUAL, &[0xFF; 12]).unwrap();
    assert_eq!(v.as_slice(), &[-1; 6]);
    // A hand-made oversized register is refused, not a panic.
    let big = Register {
        count: 7,
        ..reg::POSITION_ACTUAL
    };
    assert!(matches!(
        decode_values(&big, &[0; 14]),
        Err(RegisterError::TooManyElements { count: 7, .. })
    ));
    let huge = Register {
        count: 200,
        access: Access::ReadWrite,
        ..reg::POSITION_ACTUAL
    };
    assert_eq!(
        write_request(&huge, &[0; 200]),
        Err(EncodeError::TooMuchData(400))
    );
    assert_eq!(
        read_request(&huge),
        Request::ReadRegister {
            address: 1546,
            len: 255
        }
    );
}

#[test]
fn error_bits() {
    assert_eq!(ErrorBits(0).to_string(), "ok");
    assert!(ErrorBits(0).is_clearable());
    // The manual's example: 0x06 = over-temperature + over-current.
    let e = ErrorBits(0x06);
    assert_eq!(
        e.names().collect::<Vec<_>>(),
        ["over-temperature", "over-current"]
    );
    assert_eq!(e.to_string(), "over-temperature, over-current");
    assert!(!e.is_clearable());
    let e = ErrorBits(ErrorBits::LOCKED_ROTOR | ErrorBits::ABNORMAL | ErrorBits::COMMUNICATION);
    assert!(e.is_clearable());
    assert_eq!(
        e.to_string(),
        "locked rotor, abnormal motor operation, communication"
    );
    assert!(!ErrorBits(0x20).is_clearable());
    assert_eq!(ErrorBits(0xFF).names().count(), 8);
    assert_eq!(ErrorBits::CLEARABLE, 0x1D);
}

#[test]
fn baud_rates_and_wire_time() {
    for (code, bps, b) in [
        (0, 115_200, BaudRate::B115200),
        (1, 57_600, BaudRate::B57600),
        (2, 19_200, BaudRate::B19200),
    ] {
        assert_eq!(BaudRate::from_code(code), Some(b));
        assert_eq!(b.code(), code);
        assert_eq!(b.bits_per_second(), bps);
        assert_eq!(BaudRate::from_bps(bps), Some(b));
    }
    assert_eq!(BaudRate::from_code(3), None);
    assert_eq!(BaudRate::from_bps(9600), None);
    // 16 + 18 bytes at 115200 8N1: 340 bits = 2.951388.. ms.
    assert_eq!(wire_time(34, 115_200), Duration::from_nanos(2_951_389));
    assert_eq!(wire_time(1, 10), Duration::from_secs(1));
    assert_eq!(wire_time(0, 115_200), Duration::ZERO);
    assert_eq!(wire_time(1, 0), Duration::MAX);
    let _ = wire_time(usize::MAX, 1);
}

#[test]
fn calibration_steps() {
    let total: Duration = CALIBRATION_STEPS.iter().map(|(_, d)| *d).sum();
    assert_eq!(total, Duration::from_secs(9));
    assert_eq!(CALIBRATION_STEPS[0].1, Duration::from_secs(1));
    assert!(CALIBRATION_STEPS.iter().all(|(s, _)| !s.is_empty()));
}
