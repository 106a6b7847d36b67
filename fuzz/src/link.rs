//! The `link` fuzz target's logic (`fuzz_targets/link.rs`): arbitrary bytes
//! into the link protocol's decoder (`hopper_protocol::Decoder`), for both
//! directions' messages. Asserts that it never panics, that every message
//! it yields frames again and decodes to the same bytes, and that its
//! counts add up (each delimiter ends at most one counted frame).

use hopper_protocol::{encode, Decoder, HostMsg, RobotMsg, MAX_FRAME};

/// Feeds `data` to one decoder per direction.
pub fn run(data: &[u8]) {
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
        for i in 0..400 {
            let len = (next() % 3000) as usize;
            let mut data: Vec<u8> = (0..len).map(|_| next() as u8).collect();
            if i % 2 == 0 {
                let n = hopper_protocol::encode(&hopper_protocol::HostMsg::Heartbeat, &mut frame)
                    .unwrap_or_else(|e| panic!("{e:?}"));
                let at = (next() as usize) % (data.len() + 1);
                data.splice(at..at, frame[..n].iter().copied());
            }
            super::run(&data);
        }
    }
}
