//! CoE SDO server (ETG.1000.6 5.6.2): expedited, normal and segmented upload and download,
//! abort. No SDO information service, no complete access, never an emergency.

use crate::{mailbox::mailbox_error, AlState, Application, SdoAbort};

/// CoE header length.
const COE_HEADER: usize = 2;
/// CoE service: SDO request (also used for aborts, as real devices do).
const SERVICE_SDO_REQUEST: u16 = 0x02;
/// CoE service: SDO response.
const SERVICE_SDO_RESPONSE: u16 = 0x03;
/// CoE service: SDO information.
const SERVICE_SDO_INFO: u16 = 0x08;
/// Upper bound of a segmented download (the announced complete size).
const MAX_DOWNLOAD: usize = 64 * 1024;

/// What the server wants the mailbox layer to send.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) enum Outcome {
    /// A CoE payload (CoE header included) to send as mailbox type CoE.
    Reply(Vec<u8>),
    /// Nothing (e.g. the MainDevice aborted a transfer).
    None,
    /// Answer with a mailbox error of this detail.
    MailboxError(u16),
}

#[derive(Debug, Clone)]
enum Transfer {
    Upload {
        index: u16,
        sub: u8,
        data: Vec<u8>,
        offset: usize,
        toggle: bool,
    },
    Download {
        index: u16,
        sub: u8,
        data: Vec<u8>,
        size: usize,
        toggle: bool,
    },
}

/// SDO server state: at most one segmented transfer at a time.
#[derive(Debug, Default)]
pub(crate) struct SdoServer {
    transfer: Option<Transfer>,
    aborts: u64,
}

fn coe_header(service: u16) -> [u8; 2] {
    (service << 12).to_le_bytes()
}

fn reply(service: u16, body: &[u8]) -> Outcome {
    let mut out = Vec::with_capacity(COE_HEADER + body.len());
    out.extend_from_slice(&coe_header(service));
    out.extend_from_slice(body);
    Outcome::Reply(out)
}

fn response(cmd: u8, index: u16, sub: u8, data: &[u8]) -> Outcome {
    let i = index.to_le_bytes();
    let mut body = vec![cmd, i[0], i[1], sub];
    body.extend_from_slice(data);
    reply(SERVICE_SDO_RESPONSE, &body)
}

impl SdoServer {
    pub(crate) fn reset(&mut self) {
        self.transfer = None;
    }

    /// Number of aborts sent so far.
    pub(crate) fn aborts(&self) -> u64 {
        self.aborts
    }

    fn abort(&mut self, index: u16, sub: u8, code: SdoAbort) -> Outcome {
        self.transfer = None;
        self.aborts += 1;
        tracing::debug!(index, sub, code = code.0, "SDO abort");
        let i = index.to_le_bytes();
        let c = code.0.to_le_bytes();
        reply(
            SERVICE_SDO_REQUEST,
            &[0x80, i[0], i[1], sub, c[0], c[1], c[2], c[3]],
        )
    }

    /// Handles one CoE mailbox payload. `max_payload` is the room for the reply after the
    /// mailbox header (SM1 length - 6).
    pub(crate) fn handle<A: Application>(
        &mut self,
        app: &mut A,
        coe: &[u8],
        state: AlState,
        max_payload: usize,
    ) -> Outcome {
        if coe.len() < COE_HEADER + 1 {
            return Outcome::MailboxError(mailbox_error::SIZE_TOO_SHORT);
        }
        // Smallest possible SDO response: CoE header + 8 bytes.
        if max_payload < COE_HEADER + 8 {
            return Outcome::MailboxError(mailbox_error::NO_MORE_MEMORY);
        }
        let service = u16::from_le_bytes([coe[0], coe[1]]) >> 12;
        match service {
            SERVICE_SDO_REQUEST => self.sdo(app, &coe[COE_HEADER..], state, max_payload),
            SERVICE_SDO_INFO => Outcome::MailboxError(mailbox_error::SERVICE_NOT_SUPPORTED),
            _ => Outcome::MailboxError(mailbox_error::SERVICE_NOT_SUPPORTED),
        }
    }

    fn sdo<A: Application>(
        &mut self,
        app: &mut A,
        sdo: &[u8],
        state: AlState,
        max_payload: usize,
    ) -> Outcome {
        let cmd = sdo[0];
        match cmd >> 5 {
            1 => self.initiate_download(app, sdo, state),
            0 => self.download_segment(app, sdo, state),
            2 => self.initiate_upload(app, sdo, max_payload),
            3 => self.upload_segment(cmd, max_payload),
            4 => {
                // Abort from the MainDevice: drop the transfer, no answer.
                self.transfer = None;
                Outcome::None
            }
            _ => {
                // Block transfers (5, 6) and reserved specifiers.
                let (index, sub) = address(sdo);
                self.abort(index, sub, SdoAbort::COMMAND)
            }
        }
    }

    fn initiate_download<A: Application>(
        &mut self,
        app: &mut A,
        sdo: &[u8],
        state: AlState,
    ) -> Outcome {
        if sdo.len() < 8 {
            return Outcome::MailboxError(mailbox_error::SIZE_TOO_SHORT);
        }
        self.transfer = None;
        let cmd = sdo[0];
        let (index, sub) = address(sdo);
        if cmd & 0x10 != 0 {
            return self.abort(index, sub, SdoAbort::UNSUPPORTED_ACCESS);
        }
        let expedited = cmd & 0x02 != 0;
        let size_indicated = cmd & 0x01 != 0;
        if expedited {
            let n = if size_indicated {
                4 - usize::from((cmd >> 2) & 0x03)
            } else {
                4
            };
            return self.write(app, index, sub, &sdo[4..4 + n], state);
        }
        let available = &sdo[8..];
        let size = if size_indicated {
            u32::from_le_bytes([sdo[4], sdo[5], sdo[6], sdo[7]]) as usize
        } else {
            available.len()
        };
        if size <= available.len() {
            return self.write(app, index, sub, &available[..size], state);
        }
        if size > MAX_DOWNLOAD {
            return self.abort(index, sub, SdoAbort::OUT_OF_MEMORY);
        }
        // Segmented download: the rest follows in download segments.
        self.transfer = Some(Transfer::Download {
            index,
            sub,
            data: available.to_vec(),
            size,
            toggle: false,
        });
        response(0x60, index, sub, &[0; 4])
    }

    fn write<A: Application>(
        &mut self,
        app: &mut A,
        index: u16,
        sub: u8,
        data: &[u8],
        state: AlState,
    ) -> Outcome {
        match app.sdo_write(index, sub, data, state) {
            Ok(()) => response(0x60, index, sub, &[0; 4]),
            Err(code) => self.abort(index, sub, code),
        }
    }

    fn download_segment<A: Application>(
        &mut self,
        app: &mut A,
        sdo: &[u8],
        state: AlState,
    ) -> Outcome {
        let cmd = sdo[0];
        let Some(Transfer::Download {
            index,
            sub,
            mut data,
            size,
            toggle,
        }) = self.transfer.take()
        else {
            return self.abort(0, 0, SdoAbort::COMMAND);
        };
        let seg_toggle = cmd & 0x10 != 0;
        if seg_toggle != toggle {
            return self.abort(index, sub, SdoAbort::TOGGLE);
        }
        let payload = &sdo[1..];
        // Segments carry at least 7 bytes; shorter data says how many are unused.
        let n = if payload.len() == 7 {
            7 - usize::from((cmd >> 1) & 0x07)
        } else {
            payload.len()
        };
        data.extend_from_slice(&payload[..n]);
        let last = cmd & 0x01 != 0;
        if data.len() > size || (last && data.len() != size) {
            return self.abort(index, sub, SdoAbort::LENGTH_MISMATCH);
        }
        if last {
            if let Err(code) = app.sdo_write(index, sub, &data, state) {
                return self.abort(index, sub, code);
            }
        } else {
            self.transfer = Some(Transfer::Download {
                index,
                sub,
                data,
                size,
                toggle: !toggle,
            });
        }
        reply(
            SERVICE_SDO_RESPONSE,
            &[0x20 | (u8::from(seg_toggle) << 4), 0, 0, 0, 0, 0, 0, 0],
        )
    }

    fn initiate_upload<A: Application>(
        &mut self,
        app: &mut A,
        sdo: &[u8],
        max_payload: usize,
    ) -> Outcome {
        if sdo.len() < 4 {
            return Outcome::MailboxError(mailbox_error::SIZE_TOO_SHORT);
        }
        self.transfer = None;
        let (index, sub) = address(sdo);
        if sdo[0] & 0x10 != 0 {
            return self.abort(index, sub, SdoAbort::UNSUPPORTED_ACCESS);
        }
        let data = match app.sdo_read(index, sub) {
            Ok(data) => data,
            Err(code) => return self.abort(index, sub, code),
        };
        let n = data.len();
        if (1..=4).contains(&n) {
            let mut d = [0u8; 4];
            d[..n].copy_from_slice(&data);
            // scs = 2, expedited, size indicated, 4 - n unused bytes.
            return response(0x43 | (((4 - n) as u8) << 2), index, sub, &d);
        }
        let Ok(size) = u32::try_from(n) else {
            return self.abort(index, sub, SdoAbort::OUT_OF_MEMORY);
        };
        // Normal upload: CoE header, command, index, sub-index, complete size, data.
        let room = max_payload - (COE_HEADER + 8);
        let first = n.min(room);
        let mut body = size.to_le_bytes().to_vec();
        body.extend_from_slice(&data[..first]);
        if first < n {
            // Segmented: the initiate response carries the first part (ETG.1000.6 5.6.2.4, as
            // SOEM expects), segments carry the rest.
            self.transfer = Some(Transfer::Upload {
                index,
                sub,
                data,
                offset: first,
                toggle: false,
            });
        }
        response(0x41, index, sub, &body)
    }

    fn upload_segment(&mut self, cmd: u8, max_payload: usize) -> Outcome {
        let Some(Transfer::Upload {
            index,
            sub,
            data,
            offset,
            toggle,
        }) = self.transfer.take()
        else {
            return self.abort(0, 0, SdoAbort::COMMAND);
        };
        let seg_toggle = cmd & 0x10 != 0;
        if seg_toggle != toggle {
            return self.abort(index, sub, SdoAbort::TOGGLE);
        }
        let remaining = data.len() - offset;
        let chunk = remaining.min(max_payload - (COE_HEADER + 1));
        let last = chunk == remaining;
        let unused = if chunk < 7 { (7 - chunk) as u8 } else { 0 };
        let mut body = vec![(u8::from(seg_toggle) << 4) | (unused << 1) | u8::from(last)];
        body.extend_from_slice(&data[offset..offset + chunk]);
        body.resize(1 + chunk.max(7), 0);
        if !last {
            self.transfer = Some(Transfer::Upload {
                index,
                sub,
                data,
                offset: offset + chunk,
                toggle: !toggle,
            });
        }
        reply(SERVICE_SDO_RESPONSE, &body)
    }
}

fn address(sdo: &[u8]) -> (u16, u8) {
    match sdo {
        [_, lo, hi, sub, ..] => (u16::from_le_bytes([*lo, *hi]), *sub),
        _ => (0, 0),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use core::time::Duration;
    use std::collections::BTreeMap;

    #[derive(Default)]
    struct Od {
        objects: BTreeMap<(u16, u8), Vec<u8>>,
    }

    impl Application for Od {
        fn sdo_read(&mut self, index: u16, sub: u8) -> Result<Vec<u8>, SdoAbort> {
            self.objects
                .get(&(index, sub))
                .cloned()
                .ok_or(SdoAbort::OBJECT_DOES_NOT_EXIST)
        }
        fn sdo_write(
            &mut self,
            index: u16,
            sub: u8,
            data: &[u8],
            state: AlState,
        ) -> Result<(), SdoAbort> {
            if state != AlState::PreOp {
                return Err(SdoAbort::STATE);
            }
            self.objects.insert((index, sub), data.to_vec());
            Ok(())
        }
        fn process_image_sizes(&self) -> Result<(usize, usize), u16> {
            Ok((0, 0))
        }
        fn write_outputs(&mut self, _: &[u8], _: Duration) {}
        fn read_inputs(&mut self, _: &mut [u8], _: Duration) {}
    }

    fn req(body: &[u8]) -> Vec<u8> {
        let mut v = coe_header(SERVICE_SDO_REQUEST).to_vec();
        v.extend_from_slice(body);
        v
    }

    fn payload(o: Outcome) -> Vec<u8> {
        match o {
            Outcome::Reply(p) => p,
            other => panic!("expected a reply, got {other:?}"),
        }
    }

    #[test]
    fn expedited_upload_and_download() {
        let mut od = Od::default();
        od.objects.insert((0x2000, 1), vec![0x34, 0x12]);
        let mut s = SdoServer::default();
        let r = payload(s.handle(
            &mut od,
            &req(&[0x40, 0, 0x20, 1, 0, 0, 0, 0]),
            AlState::PreOp,
            122,
        ));
        assert_eq!(r, [0x00, 0x30, 0x4B, 0x00, 0x20, 1, 0x34, 0x12, 0, 0]);

        let r = payload(s.handle(
            &mut od,
            &req(&[0x2B, 0, 0x20, 2, 0x78, 0x56, 0, 0]),
            AlState::PreOp,
            122,
        ));
        assert_eq!(r, [0x00, 0x30, 0x60, 0x00, 0x20, 2, 0, 0, 0, 0]);
        assert_eq!(od.objects[&(0x2000, 2)], [0x78, 0x56]);
    }

    #[test]
    fn aborts_carry_codes() {
        let mut od = Od::default();
        let mut s = SdoServer::default();
        let r = payload(s.handle(
            &mut od,
            &req(&[0x40, 0x00, 0x60, 9, 0, 0, 0, 0]),
            AlState::PreOp,
            122,
        ));
        assert_eq!(r, [0x00, 0x20, 0x80, 0x00, 0x60, 9, 0x00, 0x00, 0x02, 0x06]);
        // Complete access is not offered.
        let r = payload(s.handle(
            &mut od,
            &req(&[0x50, 0x00, 0x60, 0, 0, 0, 0, 0]),
            AlState::PreOp,
            122,
        ));
        assert_eq!(&r[6..], &0x0601_0000u32.to_le_bytes());
        // Writes outside PRE-OP refused by the application.
        let r = payload(s.handle(
            &mut od,
            &req(&[0x2F, 0x00, 0x60, 1, 1, 0, 0, 0]),
            AlState::SafeOp,
            122,
        ));
        assert_eq!(&r[6..], &0x0800_0022u32.to_le_bytes());
        // Segment without a transfer.
        let r = payload(s.handle(
            &mut od,
            &req(&[0x60, 0, 0, 0, 0, 0, 0, 0]),
            AlState::PreOp,
            122,
        ));
        assert_eq!(&r[6..], &0x0504_0001u32.to_le_bytes());
        assert_eq!(s.aborts(), 4);
    }

    #[test]
    fn normal_and_segmented_upload() {
        let mut od = Od::default();
        let text: Vec<u8> = (0..20).collect();
        od.objects.insert((0x8000, 0x11), text.clone());
        let long: Vec<u8> = (0..40).collect();
        od.objects.insert((0x8000, 0x12), long.clone());
        let mut s = SdoServer::default();

        // 20 bytes fit a 32-byte reply: normal upload.
        let r = payload(s.handle(
            &mut od,
            &req(&[0x40, 0, 0x80, 0x11, 0, 0, 0, 0]),
            AlState::PreOp,
            32,
        ));
        assert_eq!(&r[2..4], &[0x41, 0x00]);
        assert_eq!(&r[6..10], &20u32.to_le_bytes());
        assert_eq!(&r[10..], &text[..]);

        // 40 bytes in a 32-byte mailbox: 22 in the initiate response, then segments of up to 29.
        let r = payload(s.handle(
            &mut od,
            &req(&[0x40, 0, 0x80, 0x12, 0, 0, 0, 0]),
            AlState::PreOp,
            32,
        ));
        assert_eq!(&r[6..10], &40u32.to_le_bytes());
        let mut got = r[10..].to_vec();
        assert_eq!(got.len(), 22);
        let mut toggle = 0u8;
        loop {
            let r = payload(s.handle(
                &mut od,
                &req(&[0x60 | toggle, 0, 0, 0, 0, 0, 0, 0]),
                AlState::PreOp,
                32,
            ));
            let cmd = r[2];
            assert_eq!(cmd & 0xE0, 0);
            assert_eq!(cmd & 0x10, toggle);
            let n = if r.len() - 3 == 7 {
                7 - usize::from((cmd >> 1) & 7)
            } else {
                r.len() - 3
            };
            got.extend_from_slice(&r[3..3 + n]);
            if cmd & 1 == 1 {
                break;
            }
            toggle ^= 0x10;
        }
        assert_eq!(got, long);

        // Wrong toggle aborts.
        let _ = s.handle(
            &mut od,
            &req(&[0x40, 0, 0x80, 0x12, 0, 0, 0, 0]),
            AlState::PreOp,
            32,
        );
        let r = payload(s.handle(
            &mut od,
            &req(&[0x70, 0, 0, 0, 0, 0, 0, 0]),
            AlState::PreOp,
            32,
        ));
        assert_eq!(&r[2..6], &[0x80, 0x00, 0x80, 0x12]);
        assert_eq!(&r[6..], &0x0503_0000u32.to_le_bytes());
    }

    #[test]
    fn normal_and_segmented_download() {
        let mut od = Od::default();
        let mut s = SdoServer::default();
        // Normal download of 6 bytes.
        let mut body = vec![0x21, 0x00, 0x80, 0x12, 6, 0, 0, 0];
        body.extend_from_slice(b"ABCDEF");
        let r = payload(s.handle(&mut od, &req(&body), AlState::PreOp, 122));
        assert_eq!(&r[2..6], &[0x60, 0x00, 0x80, 0x12]);
        assert_eq!(od.objects[&(0x8000, 0x12)], b"ABCDEF");

        // Segmented: 10 bytes announced, 4 in the initiate request, 6 in one last segment.
        let mut body = vec![0x21, 0x00, 0x80, 0x14, 10, 0, 0, 0];
        body.extend_from_slice(b"0123");
        let r = payload(s.handle(&mut od, &req(&body), AlState::PreOp, 122));
        assert_eq!(r[2], 0x60);
        // Last segment, toggle 0, 6 bytes -> 1 unused.
        let r = payload(s.handle(
            &mut od,
            &req(&[0x03, b'4', b'5', b'6', b'7', b'8', b'9', 0]),
            AlState::PreOp,
            122,
        ));
        assert_eq!(r[2], 0x20);
        assert_eq!(od.objects[&(0x8000, 0x14)], b"0123456789");
    }

    #[test]
    fn other_services_get_mailbox_errors() {
        let mut od = Od::default();
        let mut s = SdoServer::default();
        let info = (SERVICE_SDO_INFO << 12).to_le_bytes();
        assert_eq!(
            s.handle(
                &mut od,
                &[info[0], info[1], 1, 0, 0, 0],
                AlState::PreOp,
                122
            ),
            Outcome::MailboxError(mailbox_error::SERVICE_NOT_SUPPORTED)
        );
        assert_eq!(
            s.handle(&mut od, &[0, 0x20], AlState::PreOp, 122),
            Outcome::MailboxError(mailbox_error::SIZE_TOO_SHORT)
        );
    }
}
