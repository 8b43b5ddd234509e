//! A rosbag2 directory as `ros2 bag record -s mcap` writes it: one `.mcap`
//! (profile `ros2`, schemas `ros2msg` with their dependencies, messages
//! CDR) and `metadata.yaml` (version 8) listing its topics and counts.

use std::collections::BTreeMap;
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};

use super::messages::{Message, cdr};

/// One topic of the bag.
struct Topic {
    channel: u16,
    kind: &'static str,
    count: u64,
    sequence: u32,
}

/// Writes a rosbag2 directory; [`BagWriter::finish`] closes the `.mcap` and
/// writes `metadata.yaml`.
pub struct BagWriter {
    dir: PathBuf,
    file: String,
    mcap: mcap::Writer<BufWriter<File>>,
    schemas: BTreeMap<&'static str, u16>,
    topics: BTreeMap<String, Topic>,
    first_ns: Option<u64>,
    last_ns: u64,
    distro_note: String,
}

impl std::fmt::Debug for BagWriter {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("BagWriter").field("dir", &self.dir).field("topics", &self.counts()).finish()
    }
}

impl BagWriter {
    /// Creates `dir` (which must not exist: a bag is never overwritten) and
    /// its `<name>.mcap`. `note` goes into the metadata's `custom_data`
    /// (`cps_survey: …`).
    pub fn create(dir: &Path, note: &str) -> Result<Self> {
        if dir.exists() {
            bail!("{} already exists; a bag is written into a new directory", dir.display());
        }
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
        let name = dir.file_name().and_then(|n| n.to_str()).filter(|n| !n.is_empty()).unwrap_or("bag");
        let file = format!("{name}.mcap");
        let path = dir.join(&file);
        let out = File::create(&path).with_context(|| format!("creating {}", path.display()))?;
        let mcap = mcap::WriteOptions::new()
            .profile("ros2")
            .library(concat!("cps-survey ", env!("CARGO_PKG_VERSION")))
            .compression(Some(mcap::Compression::Zstd))
            .create(BufWriter::new(out))
            .with_context(|| format!("starting {}", path.display()))?;
        Ok(Self {
            dir: dir.to_path_buf(),
            file,
            mcap,
            schemas: BTreeMap::new(),
            topics: BTreeMap::new(),
            first_ns: None,
            last_ns: 0,
            distro_note: note.to_string(),
        })
    }

    /// Writes `message` on `topic` at `stamp_ns` (nanoseconds since the
    /// epoch; log and publish time).
    pub fn write<M: Message>(&mut self, topic: &str, stamp_ns: u64, message: &M) -> Result<()> {
        let data = cdr(message).with_context(|| format!("serialising a {} for {topic}", M::TYPE))?;
        let channel = self.channel::<M>(topic)?;
        let t = self.topics.get_mut(topic).context("the topic was just added")?;
        t.count += 1;
        t.sequence += 1;
        let header = mcap::records::MessageHeader {
            channel_id: channel,
            sequence: t.sequence,
            log_time: stamp_ns,
            publish_time: stamp_ns,
        };
        self.mcap.write_to_known_channel(&header, &data).with_context(|| format!("writing {topic}"))?;
        self.first_ns = Some(self.first_ns.map_or(stamp_ns, |f| f.min(stamp_ns)));
        self.last_ns = self.last_ns.max(stamp_ns);
        Ok(())
    }

    fn channel<M: Message>(&mut self, topic: &str) -> Result<u16> {
        if let Some(t) = self.topics.get(topic) {
            if t.kind != M::TYPE {
                bail!("topic {topic} carries {}, not {}", t.kind, M::TYPE);
            }
            return Ok(t.channel);
        }
        let schema = match self.schemas.get(M::TYPE) {
            Some(&id) => id,
            None => {
                let id = self.mcap.add_schema(M::TYPE, "ros2msg", M::DEFINITION.as_bytes())?;
                self.schemas.insert(M::TYPE, id);
                id
            }
        };
        let qos = BTreeMap::from([("offered_qos_profiles".to_string(), String::new())]);
        let channel = self.mcap.add_channel(schema, topic, "cdr", &qos)?;
        self.topics.insert(topic.to_string(), Topic { channel, kind: M::TYPE, count: 0, sequence: 0 });
        Ok(channel)
    }

    /// Messages written per topic.
    pub fn counts(&self) -> BTreeMap<String, u64> {
        self.topics.iter().map(|(name, t)| (name.clone(), t.count)).collect()
    }

    /// Closes the `.mcap` and writes `metadata.yaml`; returns the directory.
    pub fn finish(mut self) -> Result<PathBuf> {
        self.mcap.finish().with_context(|| format!("finishing {}", self.dir.join(&self.file).display()))?;
        let start = self.first_ns.unwrap_or(0);
        let duration = self.last_ns.saturating_sub(start);
        let count: u64 = self.topics.values().map(|t| t.count).sum();
        let q = |s: &str| serde_json::to_string(s).unwrap_or_else(|_| "\"\"".into());
        let mut y = String::new();
        y += "rosbag2_bagfile_information:\n";
        y += "  version: 8\n";
        y += "  storage_identifier: mcap\n";
        y += &format!("  duration:\n    nanoseconds: {duration}\n");
        y += &format!("  starting_time:\n    nanoseconds_since_epoch: {start}\n");
        y += &format!("  message_count: {count}\n");
        y += "  topics_with_message_count:\n";
        for (name, t) in &self.topics {
            y += "  - topic_metadata:\n";
            y += &format!("      name: {}\n      type: {}\n", q(name), q(t.kind));
            y += "      serialization_format: cdr\n      offered_qos_profiles: ''\n      type_description_hash: ''\n";
            y += &format!("    message_count: {}\n", t.count);
        }
        y += "  compression_format: ''\n  compression_mode: ''\n";
        y += &format!("  relative_file_paths:\n  - {}\n", q(&self.file));
        y += &format!(
            "  files:\n  - path: {}\n    starting_time:\n      nanoseconds_since_epoch: {start}\n    duration:\n      nanoseconds: {duration}\n    message_count: {count}\n",
            q(&self.file)
        );
        y += &format!("  custom_data:\n    cps_survey: {}\n", q(&self.distro_note));
        y += "  ros_distro: ''\n";
        let path = self.dir.join("metadata.yaml");
        let mut f = File::create(&path).with_context(|| format!("creating {}", path.display()))?;
        f.write_all(y.as_bytes()).and_then(|_| f.sync_all()).with_context(|| format!("writing {}", path.display()))?;
        Ok(self.dir)
    }
}
