//! The real ethercrab 0.7.1 MainDevice, with its own state machine, against the simulated
//! SubDevice through an in-process transport (see `common::pump`).

#![allow(missing_docs)]

mod common;

use common::{Clock, TestApp, FIRMWARE, NAME, PRODUCT, VENDOR};
use core::time::Duration;
use ethercrab::error::{CoeAbortCode, Error, MailboxError, TimeoutError};
use ethercrab::{
    AlStatusCode, MainDevice, MainDeviceConfig, PduStorage, RegisterAddress, SubDeviceState,
    Timeouts,
};
use teleop_ecat_sim::AlState;

const MAX_SUBDEVICES: usize = 2;
const MAX_PDI: usize = 64;
const MAX_FRAMES: usize = 16;
const FRAME_SIZE: usize = PduStorage::element_size(1100);

type Storage = PduStorage<MAX_FRAMES, FRAME_SIZE>;

/// Generous where ethercrab checks its timer before the awaited result (EEPROM busy loop,
/// mailbox waits), so that a loaded CI machine does not fail the tests; `pdu` is short because
/// the frame-loss test waits for it (ethercrab checks the reply before that timer); the
/// refused-transition test waits for `state_transition` once.
fn timeouts() -> Timeouts {
    Timeouts {
        pdu: Duration::from_millis(50),
        state_transition: Duration::from_millis(1000),
        eeprom: Duration::from_millis(1000),
        mailbox_echo: Duration::from_millis(1000),
        mailbox_response: Duration::from_millis(2000),
        ..Timeouts::default()
    }
}

/// Asserts that an SDO transfer was aborted with `code`; returns the aborted (index, sub-index).
fn assert_aborted<T: core::fmt::Debug>(result: Result<T, Error>, code: CoeAbortCode) -> (u16, u8) {
    match result {
        Err(Error::Mailbox(MailboxError::Aborted {
            code: got,
            address,
            sub_index,
        })) if got == code => (address, sub_index),
        other => panic!("expected SDO abort {code:?}, got {other:?}"),
    }
}

/// One cycle: advance the virtual clock by 1 ms, exchange process data.
macro_rules! cycle {
    ($group:expr, $md:expr, $clock:expr) => {{
        $clock.advance(Duration::from_millis(1));
        $group.tx_rx(&$md).await
    }};
}

#[test]
fn discovers_the_device_and_serves_sdos_in_pre_op() {
    static PDU: Storage = PduStorage::new();
    let (tx, rx, pdu_loop) = PDU.try_split().expect("split once");
    let md = MainDevice::new(pdu_loop, timeouts(), MainDeviceConfig::default());
    let sim = common::shared(TestApp::default());
    let clock = Clock::default();

    common::run(tx, rx, sim.clone(), clock, async {
        let group = md
            .init_single_group::<MAX_SUBDEVICES, MAX_PDI>(|| 0)
            .await
            .expect("init");
        assert_eq!(group.len(), 1);
        let sd = group.subdevice(&md, 0).expect("subdevice 0");
        let id = sd.identity();
        assert_eq!(
            (id.vendor_id, id.product_id, id.revision, id.serial),
            (VENDOR, PRODUCT, 1, 0x1234)
        );
        assert_eq!(sd.name(), NAME);
        assert_eq!(
            sd.status().await.expect("status"),
            (SubDeviceState::PreOp, AlStatusCode::NoError)
        );
        assert_eq!(
            sim.lock().expect("lock").al_state(),
            (AlState::PreOp, false, 0)
        );

        // Expedited reads.
        assert_eq!(sd.sdo_read::<u8>(0x2000, 1).await.expect("u8"), 0x11);
        assert_eq!(sd.sdo_read::<u16>(0x2000, 2).await.expect("u16"), 0x2222);
        assert_eq!(
            sd.sdo_read::<u32>(0x2000, 3).await.expect("u32"),
            0x3333_3333
        );
        assert_eq!(
            sd.sdo_read::<u32>(0x1018, 2).await.expect("product"),
            PRODUCT
        );
        // A 20-byte string: normal (not expedited) upload.
        assert_eq!(
            &sd.sdo_read::<[u8; 20]>(0x8000, 0x11).await.expect("string"),
            FIRMWARE
        );

        // Expedited writes.
        sd.sdo_write(0x2000, 1, 0xA5u8).await.expect("write u8");
        sd.sdo_write(0x2000, 2, 0xBEEFu16).await.expect("write u16");
        sd.sdo_write(0x2000, 3, 0xDEAD_BEEFu32)
            .await
            .expect("write u32");
        {
            let sim = sim.lock().expect("lock");
            let app = sim.app();
            assert_eq!(
                (app.p_u8, app.p_u16, app.p_u32),
                (0xA5, 0xBEEF, 0xDEAD_BEEF)
            );
        }
        assert_eq!(
            sd.sdo_read::<u16>(0x2000, 2).await.expect("u16 back"),
            0xBEEF
        );

        // Aborts surface as ethercrab errors with the code.
        assert_eq!(
            assert_aborted(
                sd.sdo_read::<u8>(0x2000, 9).await,
                CoeAbortCode::SubIndexNotFound
            ),
            (0x2000, 9)
        );
        assert_aborted(sd.sdo_read::<u8>(0x5555, 0).await, CoeAbortCode::NotFound);
        assert_aborted(
            sd.sdo_write(0x2000, 1, 0x1234u16).await,
            CoeAbortCode::DataLengthMismatch,
        );
        assert_aborted(
            sd.sdo_write(0x1018, 1, 1u32).await,
            CoeAbortCode::ReadOnlyWrite,
        );
        // Segmented upload (150 bytes > 128-byte mailbox). The simulator follows ETG.1000.6
        // and SOEM: the initiate response carries the complete size and the first 112 bytes,
        // upload segment responses (command specifier 0) the rest. ethercrab 0.7.1 cannot
        // read it: its response decoder rejects command specifier 0 (`Error::Wire`), and its
        // segmented path would also drop the data of the initiate response. A master bug that
        // shows instead of being hidden; values up to 112 bytes (normal upload) are fine.
        let long = sd.sdo_read::<[u8; 150]>(0x8000, 0x20).await;
        assert!(matches!(long, Err(Error::Wire(_))), "{long:?}");

        // The mailbox still works after aborts.
        assert_eq!(
            sd.sdo_read::<u8>(0x2000, 1).await.expect("after aborts"),
            0xA5
        );
    });

    let stats = sim.lock().expect("lock").stats();
    assert_eq!(stats.sdo_aborts, 4);
    assert_eq!(stats.mailbox_duplicates, 0);
    assert_eq!(stats.malformed, 0);
}

#[test]
fn reaches_op_and_exchanges_process_data() {
    static PDU: Storage = PduStorage::new();
    let (tx, rx, pdu_loop) = PDU.try_split().expect("split once");
    let md = MainDevice::new(pdu_loop, timeouts(), MainDeviceConfig::default());
    let sim = common::shared(TestApp::default());
    let clock = Clock::default();

    common::run(tx, rx, sim.clone(), clock.clone(), async {
        let group = md
            .init_single_group::<MAX_SUBDEVICES, MAX_PDI>(|| 0)
            .await
            .expect("init");
        // Re-assign the PDOs as an application would (sdo_write_array: sub 0 = 0, entries,
        // sub 0 = n), here to the same objects.
        let sd = group.subdevice(&md, 0).expect("subdevice 0");
        sd.sdo_write_array(0x1C12, [0x1600u16])
            .await
            .expect("assign outputs");
        sd.sdo_write_array(0x1C13, [0x1A00u16])
            .await
            .expect("assign inputs");

        let group = group.into_op(&md).await.expect("into_op");
        assert_eq!(
            sim.lock().expect("lock").al_state(),
            (AlState::Op, false, 0)
        );
        {
            let sd = group.subdevice(&md, 0).expect("subdevice 0");
            let io = sd.io_raw();
            assert_eq!((io.outputs().len(), io.inputs().len()), (4, 6));
        }

        // PDO assignment is only writable in PRE-OP.
        let sd = group.subdevice(&md, 0).expect("subdevice 0");
        assert_aborted(
            sd.sdo_write(0x1C12, 0, 0u8).await,
            CoeAbortCode::InvalidState,
        );

        for i in 0..20u8 {
            sd.io_raw_mut().outputs().copy_from_slice(&[i, 1, 2, 3]);
            sim.lock().expect("lock").app_mut().inputs = [i, 9, 8, 7, 6, 5];
            let response = cycle!(group, md, clock).expect("tx_rx");
            assert_eq!(response.working_counter, 3, "1 (inputs) + 2 (outputs)");
            assert_eq!(response.subdevice_states.as_slice(), [SubDeviceState::Op]);
            assert_eq!(sd.io_raw().inputs(), [i, 9, 8, 7, 6, 5]);
            assert_eq!(sim.lock().expect("lock").app().outputs, [i, 1, 2, 3]);
        }
        assert_eq!(sim.lock().expect("lock").app().output_count, 20);

        // SDOs keep working next to process data.
        assert_eq!(
            sd.sdo_read::<u16>(0x1C12, 1).await.expect("assignment"),
            0x1600
        );

        // Back down to INIT through the typestate API.
        let group = group.into_safe_op(&md).await.expect("into_safe_op");
        let _group = group.into_pre_op(&md).await.expect("into_pre_op");
        assert_eq!(
            sim.lock().expect("lock").al_state(),
            (AlState::PreOp, false, 0)
        );
    });
}

#[test]
fn watchdog_trips_and_the_master_recovers() {
    static PDU: Storage = PduStorage::new();
    let (tx, rx, pdu_loop) = PDU.try_split().expect("split once");
    let md = MainDevice::new(pdu_loop, timeouts(), MainDeviceConfig::default());
    let sim = common::shared(TestApp::default());
    let clock = Clock::default();

    common::run(tx, rx, sim.clone(), clock.clone(), async {
        let group = md
            .init_single_group::<MAX_SUBDEVICES, MAX_PDI>(|| 0)
            .await
            .expect("init")
            .into_op(&md)
            .await
            .expect("into_op");
        for _ in 0..5 {
            assert_eq!(cycle!(group, md, clock).expect("tx_rx").working_counter, 3);
        }

        // The cycle stops for longer than the 100 ms watchdog.
        clock.advance(Duration::from_millis(150));
        let response = group.tx_rx(&md).await.expect("tx_rx");
        assert_eq!(
            response.subdevice_states.as_slice(),
            [SubDeviceState::SafeOp]
        );
        assert_eq!(
            sim.lock().expect("lock").al_state(),
            (AlState::SafeOp, true, 0x001B)
        );
        assert_eq!(sim.lock().expect("lock").app().lost, 1);

        let sd = group.subdevice(&md, 0).expect("subdevice 0");
        let status = sd.status().await;
        assert!(
            matches!(
                status,
                Err(Error::SubDevice(AlStatusCode::SyncManagerWatchdog))
            ),
            "{status:?}"
        );
        let code = sd
            .register_read::<u16>(RegisterAddress::AlStatusCode)
            .await
            .expect("AL status code");
        assert_eq!(code, 0x001B);

        // Acknowledge the error in SAFE-OP, then request OP (docs/devices/revo2.md, "ethercrab").
        sd.register_write(RegisterAddress::AlControl, 0x0014u16)
            .await
            .expect("acknowledge");
        assert_eq!(
            sd.status().await.expect("status"),
            (SubDeviceState::SafeOp, AlStatusCode::NoError)
        );
        sd.register_write(RegisterAddress::AlControl, 0x0008u16)
            .await
            .expect("request OP");
        let response = cycle!(group, md, clock).expect("tx_rx");
        assert_eq!(response.subdevice_states.as_slice(), [SubDeviceState::Op]);
        assert_eq!(response.working_counter, 3);
        assert_eq!(
            sim.lock().expect("lock").al_state(),
            (AlState::Op, false, 0)
        );

        // Forced trip (fault injection) is seen the same way.
        sim.lock().expect("lock").trip_watchdog();
        let response = cycle!(group, md, clock).expect("tx_rx");
        assert_eq!(
            response.subdevice_states.as_slice(),
            [SubDeviceState::SafeOp]
        );
    });
    assert_eq!(sim.lock().expect("lock").stats().watchdog_trips, 2);
}

#[test]
fn refused_transitions_surface_with_their_al_status_code() {
    static PDU: Storage = PduStorage::new();
    let (tx, rx, pdu_loop) = PDU.try_split().expect("split once");
    let md = MainDevice::new(pdu_loop, timeouts(), MainDeviceConfig::default());
    let sim = common::shared(TestApp::default());
    let clock = Clock::default();

    common::run(tx, rx, sim.clone(), clock.clone(), async {
        let group = md
            .init_single_group::<MAX_SUBDEVICES, MAX_PDI>(|| 0)
            .await
            .expect("init");

        // ethercrab's typestate API does not read the error flag while it waits for the state:
        // a refused PRE-OP -> SAFE-OP ends in a state transition timeout...
        sim.lock().expect("lock").faults().refuse_next_transition = Some(0x0024);
        let result = group.into_op(&md).await;
        assert!(
            matches!(result, Err(Error::Timeout(TimeoutError::StateTransition))),
            "{:?}",
            result.as_ref().err()
        );
        // ...while the SubDevice shows PRE-OP + ERR with the code.
        assert_eq!(
            sim.lock().expect("lock").al_state(),
            (AlState::PreOp, true, 0x0024)
        );

        // A new init acknowledges (AL control 0x11) and starts over.
        let group = md
            .init_single_group::<MAX_SUBDEVICES, MAX_PDI>(|| 0)
            .await
            .expect("init again");
        let group = group.into_safe_op(&md).await.expect("into_safe_op");

        // Through the register API the code is visible as an ethercrab error.
        sim.lock().expect("lock").faults().refuse_next_transition = Some(0x001A);
        let sd = group.subdevice(&md, 0).expect("subdevice 0");
        sd.register_write(RegisterAddress::AlControl, 0x0008u16)
            .await
            .expect("request OP");
        let status = sd.status().await;
        assert!(
            matches!(
                status,
                Err(Error::SubDevice(AlStatusCode::SynchronizationError))
            ),
            "{status:?}"
        );
        // Higher states are ignored until the error is acknowledged.
        sd.register_write(RegisterAddress::AlControl, 0x0008u16)
            .await
            .expect("request OP again");
        assert_eq!(
            sim.lock().expect("lock").al_state(),
            (AlState::SafeOp, true, 0x001A)
        );
        sd.register_write(RegisterAddress::AlControl, 0x0018u16)
            .await
            .expect("acknowledge and request OP");
        let group = group.into_op(&md).await.expect("already in OP");
        assert_eq!(cycle!(group, md, clock).expect("tx_rx").working_counter, 3);

        // An invalid request (OP -> BOOT) gives 0x0011.
        let sd = group.subdevice(&md, 0).expect("subdevice 0");
        sd.register_write(RegisterAddress::AlControl, 0x0003u16)
            .await
            .expect("request BOOT");
        let status = sd.status().await;
        assert!(
            matches!(
                status,
                Err(Error::SubDevice(AlStatusCode::InvalidRequestedStateChange))
            ),
            "{status:?}"
        );
    });
    assert_eq!(sim.lock().expect("lock").stats().injected_refusals, 2);
}

#[test]
fn lost_frames_and_wrong_working_counters() {
    static PDU: Storage = PduStorage::new();
    let (tx, rx, pdu_loop) = PDU.try_split().expect("split once");
    let md = MainDevice::new(pdu_loop, timeouts(), MainDeviceConfig::default());
    let sim = common::shared(TestApp::default());
    let clock = Clock::default();

    common::run(tx, rx, sim.clone(), clock.clone(), async {
        let group = md
            .init_single_group::<MAX_SUBDEVICES, MAX_PDI>(|| 0)
            .await
            .expect("init")
            .into_op(&md)
            .await
            .expect("into_op");
        assert_eq!(cycle!(group, md, clock).expect("tx_rx").working_counter, 3);

        // Frame loss: ethercrab times out, the next cycle works.
        sim.lock().expect("lock").faults().drop_probability = 1.0;
        let lost = cycle!(group, md, clock);
        assert!(
            matches!(lost, Err(Error::Timeout(TimeoutError::Pdu))),
            "{lost:?}"
        );
        sim.lock().expect("lock").faults().drop_probability = 0.0;
        assert_eq!(cycle!(group, md, clock).expect("tx_rx").working_counter, 3);

        // Cable pulled, then plugged back.
        sim.lock().expect("lock").faults().link_down = true;
        assert!(matches!(
            cycle!(group, md, clock),
            Err(Error::Timeout(TimeoutError::Pdu))
        ));
        sim.lock().expect("lock").faults().link_down = false;
        assert_eq!(cycle!(group, md, clock).expect("tx_rx").working_counter, 3);

        // A wrong working counter is visible (tx_rx does not check it).
        sim.lock().expect("lock").faults().wrong_wkc_probability = 1.0;
        let response = cycle!(group, md, clock).expect("tx_rx");
        assert_eq!(response.working_counter, 2);
        assert_eq!(response.subdevice_states.as_slice(), [SubDeviceState::Op]);
        sim.lock().expect("lock").faults().wrong_wkc_probability = 0.0;
        assert_eq!(cycle!(group, md, clock).expect("tx_rx").working_counter, 3);
    });
    let stats = sim.lock().expect("lock").stats();
    assert_eq!((stats.dropped_frames, stats.wrong_wkc), (2, 1));
}

#[test]
fn four_byte_sii_reads() {
    static PDU: Storage = PduStorage::new();
    let (tx, rx, pdu_loop) = PDU.try_split().expect("split once");
    let md = MainDevice::new(pdu_loop, timeouts(), MainDeviceConfig::default());
    let sim = common::shared(TestApp::default());
    sim.lock().expect("lock").set_sii_8_byte_reads(false);
    let clock = Clock::default();

    common::run(tx, rx, sim.clone(), clock.clone(), async {
        let group = md
            .init_single_group::<MAX_SUBDEVICES, MAX_PDI>(|| 0)
            .await
            .expect("init");
        let sd = group.subdevice(&md, 0).expect("subdevice 0");
        assert_eq!(sd.identity().vendor_id, VENDOR);
        assert_eq!(sd.name(), NAME);
        let eeprom_bytes = sd.eeprom_size(&md).await.expect("EEPROM size");
        assert_eq!(eeprom_bytes, sim.lock().expect("lock").sii_image().len());
        let group = group.into_op(&md).await.expect("into_op");
        assert_eq!(cycle!(group, md, clock).expect("tx_rx").working_counter, 3);
    });
}
