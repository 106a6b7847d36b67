//! The `link` fuzz target's logic (`fuzz_targets/link.rs`): arbitrary bytes
//! into the link protocol's decoder (`hopper_protocol::Decoder`), for both
//! directions' messages. Asserts that it never panics, that every message
//! it yields frames again and decodes to the same bytes, and that its
//! counts add up (each delimiter ends at most one counted frame). Then the
//! same bytes go to the robot's end (the link task,
//! [`hopper_robot_link::Endpoint`], and the control period's
//! [`hopper_robot_link::ControlPort`]) on a period runner, a chunk per period, as a UART would deliver them:
//! whatever the requests (parameter sets, arm, dumps, ...), nothing
//! panics and everything the robot sends is a well-formed frame.

use hopper_control::hal::{HopperIo, IoError, RawSample};
use hopper_control::hopper::HopperConfig;
use hopper_robot_link::{ControlPort, Endpoint, Queues, Tx};
use hopper_control::runner::{NoCounter, PeriodRunner, Timing};
use hopper_control::telemetry::FaultCapture;
use hopper_protocol::{encode, Decoder, HostMsg, RobotMsg, MAX_FRAME};

struct RestIo(RawSample);

impl HopperIo for RestIo {
    type Error = ();
    fn read(&mut self) -> Result<RawSample, IoError<()>> {
        Ok(self.0)
    }
    fn write_dac(&mut self, _: u16) -> Result<(), IoError<()>> {
        Ok(())
    }
    fn set_amp_enabled(&mut self, _: bool) -> Result<(), IoError<()>> {
        Ok(())
    }
}

struct VecTx(Vec<u8>);

impl Tx for VecTx {
    fn room(&self) -> usize {
        4096usize.saturating_sub(self.0.len())
    }
    fn put(&mut self, frame: &[u8]) {
        self.0.extend_from_slice(frame);
    }
}

/// `data` into a robot's endpoint, up to 32 bytes a period; the number of
/// responses it sent.
fn endpoint(data: &[u8]) -> usize {
    let cfg = HopperConfig::default();
    let Ok(mut runner) = PeriodRunner::new(cfg, Timing::default()) else {
        panic!("the default configuration must build");
    };
    let cal = cfg.calibration;
    let mut io = RestIo(RawSample {
        pot_code: cal.pot_offset_code as u16,
        loadcell_code: cal.loadcell_offset_code as u16,
        ..RawSample::default()
    });
    let mut port = ControlPort::new();
    let mut ep = Endpoint::simulated(&runner);
    let mut q = Box::<Queues>::default();
    let mut capture: FaultCapture<64> = FaultCapture::new();
    let mut tx = VecTx(Vec::new());
    let mut host = Decoder::new();
    let mut last_seq: Option<u32> = None;
    let mut responses = 0;
    for chunk in data.chunks(32).chain(core::iter::repeat_n(&[][..], 8)) {
        let p = runner.run_period(&mut io, &mut NoCounter);
        runner.end_period(false);
        port.after_period(
            &mut runner,
            &p,
            &mut capture,
            &mut q.commands,
            &mut q.answers,
            &mut q.notes,
            &mut q.stats,
            &mut q.logs,
        );
        ep.service(
            &mut q.notes,
            &mut q.stats,
            &mut q.logs,
            &mut q.answers,
            &mut q.commands,
            chunk.iter().copied(),
            &mut &mut capture,
            &mut tx,
            &mut NoCounter,
        );
        for &b in &tx.0 {
            match host.push::<RobotMsg>(b) {
                Some(RobotMsg::Telemetry(t)) => {
                    assert!(last_seq.is_none_or(|s| t.seq > s), "telemetry out of order");
                    last_seq = Some(t.seq);
                }
                Some(RobotMsg::Response { .. }) => responses += 1,
                _ => {}
            }
        }
        tx.0.clear();
        assert_eq!(host.stats().bad(), 0, "the robot sent a bad frame");
    }
    responses
}

/// Feeds `data` to one decoder per direction, then to a robot's endpoint;
/// the number of responses the robot sent.
pub fn run(data: &[u8]) -> usize {
    let responses = endpoint(data);
    let mut host = Decoder::new();
    let mut robot = Decoder::new();
    let mut yielded = 0u32;
    for &b in data {
        if let Some(m) = host.push::<HostMsg>(b) {
            yielded += 1;
            round_trip(&m);
        }
        if let Some(m) = robot.push::<RobotMsg>(b) {
            round_trip(&m);
        }
    }
    let delimiters = data.iter().filter(|b| **b == 0).count();
    let s = host.stats();
    assert_eq!(s.ok, yielded);
    assert!((s.ok + s.bad()) as usize <= delimiters, "{s:?}");
    responses
}

fn round_trip<T: serde::Serialize + for<'de> serde::Deserialize<'de>>(m: &T) {
    let mut frame = [0u8; MAX_FRAME];
    let n = encode(m, &mut frame).unwrap_or_else(|e| panic!("a decoded message must frame: {e:?}"));
    let mut d = Decoder::new();
    let back = frame[..n].iter().find_map(|&b| d.push::<T>(b));
    let mut again = [0u8; MAX_FRAME];
    let k = back
        .as_ref()
        .map(|b| encode(b, &mut again).unwrap_or_else(|e| panic!("{e:?}")))
        .unwrap_or_else(|| panic!("a framed message must decode"));
    assert_eq!(frame[..n], again[..k]);
}

#[cfg(test)]
mod tests {
    /// Random bytes, and random bytes with good frames spliced in.
    #[test]
    fn random_bytes_and_spliced_frames() {
        let mut x: u64 = 0x11AC_0017;
        let mut next = || {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            x
        };
        let mut frame = [0u8; hopper_protocol::MAX_FRAME];
        let mut answered = 0;
        for i in 0..400 {
            let len = (next() % 3000) as usize;
            let mut data: Vec<u8> = (0..len).map(|_| next() as u8).collect();
            if i % 2 == 0 {
                // A good request of every kind, with random arguments (a
                // table name or not, any value), spliced into the noise.
                use hopper_protocol::{HostMsg, Name, Request};
                let table = hopper_control::params::TABLE;
                let mut name = Name::new();
                let _ = name.push_str(if next() % 4 == 0 {
                    "no.such"
                } else {
                    table[(next() as usize) % table.len()].name
                });
                let value = f32::from_bits(next() as u32);
                let value = if next() % 2 == 0 {
                    value
                } else {
                    (next() % 10) as f32 * 0.1
                };
                let reqs = [
                    Request::Status,
                    Request::Arm,
                    Request::Disarm,
                    Request::ResetFaults,
                    Request::ParamCount,
                    Request::ParamInfo {
                        index: next() as u16 % 120,
                    },
                    Request::ParamGet { name: name.clone() },
                    Request::ParamSet { name, value },
                    Request::Telemetry {
                        every: next() as u16 % 4,
                    },
                    Request::Timing,
                    Request::Dump,
                    Request::SimulateEstop {
                        pressed: next() % 2 == 0,
                    },
                    Request::LinkCounts,
                ];
                for (id, req) in reqs.into_iter().enumerate() {
                    if next() % 3 == 0 {
                        continue;
                    }
                    let msg = HostMsg::Request { id: id as u16, req };
                    let n = hopper_protocol::encode(&msg, &mut frame)
                        .unwrap_or_else(|e| panic!("{e:?}"));
                    let at = (next() as usize) % (data.len() + 1);
                    // A delimiter first: the noise before it is one bad frame.
                    data.splice(
                        at..at,
                        core::iter::once(0).chain(frame[..n].iter().copied()),
                    );
                }
            }
            answered += super::run(&data);
        }
        // The spliced requests reached the endpoint and were answered.
        assert!(answered > 500, "{answered} responses");
    }
}
