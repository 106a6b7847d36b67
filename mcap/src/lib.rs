//! MCAP recordings: what `hopper-link record` and `hopper-sim run --out`
//! write as `telemetry.mcap`, for the viewers robotics labs use (Foxglove,
//! PlotJuggler). Each channel carries JSON messages (`message_encoding`
//! `json`) described by a JSON schema (`jsonschema`), and each message is
//! stamped with robot time (the control period's count times its length;
//! a simulation's time), in nanoseconds, as its log and publish time.
//! Chunks are uncompressed: any reader opens them without a codec.
//!
//! [`Mcap::flush`] closes the open chunk, so a recording cut short (Ctrl-C,
//! a closed link) is readable up to there; [`Mcap::finish`] writes the
//! summary and the footer.

use std::collections::BTreeMap;
use std::fs::File;
use std::io::BufWriter;
use std::path::Path;

/// One field of a channel's messages, for its JSON schema.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Field {
    /// The field's name (with its unit: `body_height_m`).
    pub name: &'static str,
    /// Its JSON type: `number`, `integer`, `string` or `boolean`.
    pub kind: &'static str,
    /// What it is.
    pub doc: &'static str,
}

/// The hop ledger's fields (the firmware's `HopLedger`, the wire's `Hop`),
/// the `/hop` channel's schema in every recording.
pub const HOP_FIELDS: [Field; 10] = [
    field("hop", "integer", "hop number (1 = the first stance)"),
    field(
        "apex_height_m",
        "number",
        "apex toe height after the stance, m",
    ),
    field(
        "energy_at_touchdown_j",
        "number",
        "estimated energy just after touchdown, J",
    ),
    field(
        "energy_at_liftoff_j",
        "number",
        "estimated energy just after liftoff, J",
    ),
    field("stance_work_j", "number", "the motor's work in stance, J"),
    field("stance_duration_s", "number", "stance duration, s"),
    field("peak_current_a", "number", "peak commanded current, A"),
    field("peak_stroke_m", "number", "peak nut stroke, m"),
    field(
        "copper_loss_j",
        "number",
        "the motor's copper loss from the previous apex to this one, J",
    ),
    field(
        "stance_copper_loss_j",
        "number",
        "the part of the copper loss in stance, J",
    ),
];

/// A latched fault's fields, the `/fault` channel's schema (a simulation
/// gives the names only).
pub const FAULT_FIELDS: [Field; 3] = [
    field("step", "integer", "control period the faults latched in"),
    field("bits", "integer", "the fault bits"),
    field("faults", "string", "the faults by name"),
];

/// A [`Field`], for tables of them.
pub const fn field(name: &'static str, kind: &'static str, doc: &'static str) -> Field {
    Field { name, kind, doc }
}

/// An MCAP file being written.
pub struct Mcap {
    writer: mcap::Writer<BufWriter<File>>,
    sequence: u32,
}

/// A channel of an [`Mcap`] file.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Channel(u16);

fn err(what: &str, path: &Path, e: impl std::fmt::Display) -> String {
    format!("cannot {what} {}: {e}", path.display())
}

impl Mcap {
    /// Creates the file at `path`.
    pub fn create(path: &Path) -> Result<Self, String> {
        let file = File::create(path).map_err(|e| err("write", path, e))?;
        let writer = mcap::WriteOptions::new()
            .compression(None)
            .profile("")
            .library(concat!("hopper ", env!("CARGO_PKG_VERSION")))
            .create(BufWriter::new(file))
            .map_err(|e| err("write", path, e))?;
        Ok(Self {
            writer,
            sequence: 0,
        })
    }

    /// A channel `topic` whose messages are objects of `fields`, its schema
    /// named `schema`.
    pub fn channel(
        &mut self,
        topic: &str,
        schema: &str,
        fields: &[Field],
    ) -> Result<Channel, String> {
        let properties: serde_json::Map<String, serde_json::Value> = fields
            .iter()
            .map(|f| {
                (
                    f.name.to_string(),
                    serde_json::json!({ "type": f.kind, "description": f.doc }),
                )
            })
            .collect();
        self.channel_with(
            topic,
            schema,
            &serde_json::json!({ "type": "object", "properties": properties }),
        )
    }

    /// A channel `topic` whose messages are objects of numbers by name
    /// (the parameters: a `null` for one the configuration lacks).
    pub fn map_channel(&mut self, topic: &str, schema: &str) -> Result<Channel, String> {
        self.channel_with(
            topic,
            schema,
            &serde_json::json!({
                "type": "object",
                "additionalProperties": { "type": ["number", "null"] }
            }),
        )
    }

    fn channel_with(
        &mut self,
        topic: &str,
        schema: &str,
        json_schema: &serde_json::Value,
    ) -> Result<Channel, String> {
        let data = serde_json::to_vec(json_schema).map_err(|e| e.to_string())?;
        let schema_id = self
            .writer
            .add_schema(schema, "jsonschema", &data)
            .map_err(|e| e.to_string())?;
        let id = self
            .writer
            .add_channel(schema_id, topic, "json", &BTreeMap::new())
            .map_err(|e| e.to_string())?;
        Ok(Channel(id))
    }

    /// Writes `message` on `channel` at robot time `time_s`.
    pub fn log(
        &mut self,
        channel: Channel,
        time_s: f64,
        message: &impl serde::Serialize,
    ) -> Result<(), String> {
        let data = serde_json::to_vec(message).map_err(|e| e.to_string())?;
        // Robot time from 0: a negative or non-finite one is 0.
        let t_ns = if time_s.is_finite() && time_s > 0.0 {
            (time_s * 1e9).round() as u64
        } else {
            0
        };
        self.writer
            .write_to_known_channel(
                &mcap::records::MessageHeader {
                    channel_id: channel.0,
                    sequence: self.sequence,
                    log_time: t_ns,
                    publish_time: t_ns,
                },
                &data,
            )
            .map_err(|e| e.to_string())?;
        self.sequence = self.sequence.wrapping_add(1);
        Ok(())
    }

    /// Closes the open chunk and flushes the file: readable up to here.
    pub fn flush(&mut self) -> Result<(), String> {
        self.writer.flush().map_err(|e| e.to_string())
    }

    /// Writes the summary and the footer.
    pub fn finish(mut self) -> Result<(), String> {
        self.writer.finish().map(|_| ()).map_err(|e| e.to_string())
    }
}

pub mod read {
    //! A reader of what [`super::Mcap`] writes, from the MCAP
    //! specification (mcap.dev/spec) rather than the writing crate, so a
    //! test that reads a recording back checks the bytes against the
    //! format, not the writer against itself: the magic at both ends,
    //! every record's opcode and length, the channels, and the messages,
    //! in the data section or in uncompressed chunks.

    use std::collections::BTreeMap;

    /// The file's first and last eight bytes.
    pub const MAGIC: [u8; 8] = [0x89, b'M', b'C', b'A', b'P', b'0', b'\r', b'\n'];

    const CHANNEL: u8 = 0x04;
    const MESSAGE: u8 = 0x05;
    const CHUNK: u8 = 0x06;
    const FOOTER: u8 = 0x02;

    /// One message as read.
    #[derive(Debug, Clone, PartialEq)]
    pub struct Message {
        /// Its channel's topic.
        pub topic: String,
        /// Its sequence number.
        pub sequence: u32,
        /// Its log time, ns.
        pub log_time_ns: u64,
        /// Its data, parsed as JSON.
        pub json: serde_json::Value,
    }

    struct Bytes<'a>(&'a [u8]);

    impl<'a> Bytes<'a> {
        fn take(&mut self, n: usize) -> Result<&'a [u8], String> {
            if self.0.len() < n {
                return Err(format!(
                    "truncated: {n} bytes wanted, {} left",
                    self.0.len()
                ));
            }
            let (a, b) = self.0.split_at(n);
            self.0 = b;
            Ok(a)
        }
        fn u8(&mut self) -> Result<u8, String> {
            Ok(self.take(1)?[0])
        }
        fn u16(&mut self) -> Result<u16, String> {
            let b = self.take(2)?;
            Ok(u16::from_le_bytes([b[0], b[1]]))
        }
        fn u32(&mut self) -> Result<u32, String> {
            let mut a = [0u8; 4];
            a.copy_from_slice(self.take(4)?);
            Ok(u32::from_le_bytes(a))
        }
        fn u64(&mut self) -> Result<u64, String> {
            let mut a = [0u8; 8];
            a.copy_from_slice(self.take(8)?);
            Ok(u64::from_le_bytes(a))
        }
        fn string(&mut self) -> Result<String, String> {
            let n = self.u32()? as usize;
            String::from_utf8(self.take(n)?.to_vec()).map_err(|e| e.to_string())
        }
    }

    /// Reads records from `b` until it ends (a chunk's records) or a
    /// footer (the file's), collecting channels and messages.
    fn records(
        b: &mut Bytes<'_>,
        topics: &mut BTreeMap<u16, String>,
        raw: &mut Vec<(u16, u32, u64, Vec<u8>)>,
    ) -> Result<bool, String> {
        while !b.0.is_empty() {
            let op = b.u8()?;
            let len = usize::try_from(b.u64()?).map_err(|e| e.to_string())?;
            let mut r = Bytes(b.take(len)?);
            match op {
                CHANNEL => {
                    let id = r.u16()?;
                    let _schema = r.u16()?;
                    let topic = r.string()?;
                    let encoding = r.string()?;
                    if encoding != "json" {
                        return Err(format!("channel {topic}: encoding {encoding}"));
                    }
                    topics.insert(id, topic);
                }
                MESSAGE => {
                    let channel = r.u16()?;
                    let sequence = r.u32()?;
                    let log_time = r.u64()?;
                    let _publish = r.u64()?;
                    raw.push((channel, sequence, log_time, r.0.to_vec()));
                }
                CHUNK => {
                    let _start = r.u64()?;
                    let _end = r.u64()?;
                    let size = r.u64()?;
                    let _crc = r.u32()?;
                    let compression = r.string()?;
                    if !compression.is_empty() {
                        return Err(format!("a chunk compressed with {compression}"));
                    }
                    let n = usize::try_from(r.u64()?).map_err(|e| e.to_string())?;
                    let inner = r.take(n)?;
                    if inner.len() as u64 != size {
                        return Err(format!("a chunk of {} bytes says {size}", inner.len()));
                    }
                    records(&mut Bytes(inner), topics, raw)?;
                }
                FOOTER => return Ok(true),
                _ => {}
            }
        }
        Ok(false)
    }

    /// Every message of the MCAP file `bytes`, in file order.
    pub fn messages(bytes: &[u8]) -> Result<Vec<Message>, String> {
        if bytes.len() < 16 || bytes[..8] != MAGIC || bytes[bytes.len() - 8..] != MAGIC {
            return Err("not an MCAP file (the magic is missing at an end)".into());
        }
        let mut b = Bytes(&bytes[8..bytes.len() - 8]);
        let mut topics = BTreeMap::new();
        let (mut out, mut raw) = (Vec::new(), Vec::new());
        if !records(&mut b, &mut topics, &mut raw)? {
            return Err("no footer".into());
        }
        if !b.0.is_empty() {
            return Err(format!("{} bytes after the footer", b.0.len()));
        }
        for (channel, sequence, log_time_ns, data) in raw {
            let topic = topics
                .get(&channel)
                .cloned()
                .ok_or_else(|| format!("a message on unknown channel {channel}"))?;
            let json = serde_json::from_slice(&data).map_err(|e| format!("{topic}: {e}"))?;
            out.push(Message {
                topic,
                sequence,
                log_time_ns,
                json,
            });
        }
        Ok(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn what_is_written_reads_back() {
        let path = std::env::temp_dir().join(format!("hopper-mcap-{}.mcap", std::process::id()));
        let mut m = Mcap::create(&path).unwrap_or_else(|e| panic!("{e}"));
        let t = m
            .channel(
                "/telemetry",
                "hopper.Telemetry",
                &[Field {
                    name: "body_height_m",
                    kind: "number",
                    doc: "body height",
                }],
            )
            .unwrap_or_else(|e| panic!("{e}"));
        let p = m
            .map_channel("/parameters", "hopper.Parameters")
            .unwrap_or_else(|e| panic!("{e}"));
        m.log(
            p,
            0.0,
            &serde_json::json!({ "target_apex_m": 0.1, "energy.gain": null }),
        )
        .unwrap_or_else(|e| panic!("{e}"));
        for i in 0..1000 {
            m.log(
                t,
                f64::from(i) * 1e-3,
                &serde_json::json!({ "body_height_m": f64::from(i) }),
            )
            .unwrap_or_else(|e| panic!("{e}"));
            if i == 500 {
                m.flush().unwrap_or_else(|e| panic!("{e}"));
            }
        }
        m.finish().unwrap_or_else(|e| panic!("{e}"));
        let bytes = std::fs::read(&path).unwrap_or_else(|e| panic!("{e}"));
        let _ = std::fs::remove_file(&path);
        let msgs = read::messages(&bytes).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(msgs.len(), 1001);
        assert_eq!(msgs[0].topic, "/parameters");
        assert_eq!(msgs[0].json["energy.gain"], serde_json::Value::Null);
        let last = &msgs[1000];
        assert_eq!(
            (last.topic.as_str(), last.sequence, last.log_time_ns),
            ("/telemetry", 1000, 999_000_000)
        );
        assert_eq!(last.json["body_height_m"], 999.0);
        // Cut anywhere, it is not a recording.
        assert!(read::messages(&bytes[..bytes.len() - 1]).is_err());
    }
}
