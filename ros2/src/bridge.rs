//! The DDS side: one participant, one writer per ROS 2 topic, sensor-data QoS.

use std::cell::Cell;
use std::net::IpAddr;

use anyhow::Context;
use dear_capture::Intrinsics;
use dear_client::{CameraIntrinsics, Rays};
use rustdds::no_key::DataWriter;
use rustdds::policy::{Durability, History, Reliability};
use rustdds::{
    CDRSerializerAdapter, DataWriterStatus, DomainParticipant, DomainParticipantBuilder,
    QosPolicies, QosPolicyBuilder, StatusEvented, TopicKind,
};
use serde::Serialize;

use crate::convert::{self, DepthEncoding, Planes};
use crate::msg::{CameraInfo, Image, PointCloud2, CAMERA_INFO_TYPE, IMAGE_TYPE, POINT_CLOUD2_TYPE};

/// `rmw_qos_profile_sensor_data`: best effort, keep last 5, volatile.
pub fn sensor_data_qos() -> QosPolicies {
    QosPolicyBuilder::new()
        .reliability(Reliability::BestEffort)
        .durability(Durability::Volatile)
        .history(History::KeepLast { depth: 5 })
        .build()
}

/// What the bridge publishes and how.
#[derive(Debug, Clone)]
pub struct Options {
    /// DDS domain (ROS_DOMAIN_ID).
    pub domain_id: u16,
    /// Topics' namespace, `/dear/cam0`.
    pub namespace: String,
    /// `frame_id` of every message.
    pub frame_id: String,
    pub depth_encoding: DepthEncoding,
    /// `--intrinsics`: the RGB camera's pinhole, instead of the intrinsics each frame header
    /// carries. A frame with neither gets no CameraInfo and no PointCloud2.
    pub intrinsics: Option<Intrinsics>,
    /// Publish `depth/points`.
    pub cloud: bool,
    /// Give the points the `rgb` field.
    pub cloud_rgb: bool,
    /// Only these local addresses for DDS traffic and discovery (empty: all).
    pub interfaces: Vec<IpAddr>,
}

type Writer<T> = DataWriter<T, CDRSerializerAdapter<T>>;

/// One topic's writer.
struct Topic<T: Serialize> {
    name: String,
    writer: Writer<T>,
    /// Readers matched now, from the writer's `PublicationMatched` statuses.
    matched: Cell<i32>,
}

impl<T: Serialize> Topic<T> {
    fn new(
        participant: &DomainParticipant,
        publisher: &rustdds::Publisher,
        name: String,
        type_name: &str,
    ) -> anyhow::Result<Self> {
        let qos = sensor_data_qos();
        // ROS 2 topic `/a/b` is the DDS topic `rt/a/b`.
        let dds_name = format!("rt{name}");
        let topic = participant
            .create_topic(dds_name, type_name.to_string(), &qos, TopicKind::NoKey)
            .map_err(|e| anyhow::anyhow!("cannot create DDS topic for {name}: {e:?}"))?;
        let writer = publisher
            .create_datawriter_no_key::<T, CDRSerializerAdapter<T>>(&topic, None)
            .map_err(|e| anyhow::anyhow!("cannot create DDS writer for {name}: {e:?}"))?;
        Ok(Topic {
            name,
            writer,
            matched: Cell::new(0),
        })
    }

    /// Whether any reader matched this topic: messages nobody would receive are not made.
    fn wanted(&self) -> bool {
        while let Some(status) = self.writer.try_recv_status() {
            if let DataWriterStatus::PublicationMatched { current, .. } = status {
                self.matched.set(current.count());
            }
        }
        self.matched.get() > 0
    }

    fn write(&self, message: T) -> anyhow::Result<()> {
        self.writer
            .write(message, None)
            .map_err(|e| anyhow::anyhow!("publishing {} failed: {e}", self.name))
    }
}

/// The participant and the writers of every topic.
pub struct Bridge {
    options: Options,
    depth: Topic<Image>,
    color: Topic<Image>,
    confidence: Topic<Image>,
    depth_info: Option<Topic<CameraInfo>>,
    color_info: Option<Topic<CameraInfo>>,
    points: Option<Topic<PointCloud2>>,
    /// The point cloud's rays, made again only when the intrinsics or the size change.
    rays: Option<Rays>,
    // Dropped last: the writers need it.
    _participant: DomainParticipant,
}

impl Bridge {
    pub fn new(options: Options) -> anyhow::Result<Self> {
        let mut builder = DomainParticipantBuilder::new(options.domain_id);
        if !options.interfaces.is_empty() {
            builder = builder.with_only_networks(options.interfaces.iter().copied());
        }
        let participant = builder
            .build()
            .map_err(|e| anyhow::anyhow!("{e:?}"))
            .with_context(|| format!("cannot join DDS domain {}", options.domain_id))?;
        let publisher = participant
            .create_publisher(&sensor_data_qos())
            .map_err(|e| anyhow::anyhow!("cannot create a DDS publisher: {e:?}"))?;
        let ns = &options.namespace;
        let image =
            |leaf: &str| Topic::new(&participant, &publisher, format!("{ns}/{leaf}"), IMAGE_TYPE);
        let info = |leaf: &str| {
            Topic::new(
                &participant,
                &publisher,
                format!("{ns}/{leaf}"),
                CAMERA_INFO_TYPE,
            )
        };
        Ok(Bridge {
            depth: image("depth/image_raw")?,
            color: image("color/image_raw")?,
            confidence: image("confidence/image_raw")?,
            depth_info: Some(info("depth/camera_info")?),
            color_info: Some(info("color/camera_info")?),
            points: options
                .cloud
                .then(|| {
                    Topic::new(
                        &participant,
                        &publisher,
                        format!("{ns}/depth/points"),
                        POINT_CLOUD2_TYPE,
                    )
                })
                .transpose()?,
            rays: None,
            options,
            _participant: participant,
        })
    }

    /// The ROS 2 names of the topics published, with their types.
    pub fn topics(&self) -> Vec<(&str, &str)> {
        let mut t = vec![
            (self.depth.name.as_str(), "sensor_msgs/msg/Image"),
            (self.color.name.as_str(), "sensor_msgs/msg/Image"),
            (self.confidence.name.as_str(), "sensor_msgs/msg/Image"),
        ];
        for info in [&self.depth_info, &self.color_info].into_iter().flatten() {
            t.push((info.name.as_str(), "sensor_msgs/msg/CameraInfo"));
        }
        if let Some(points) = &self.points {
            t.push((points.name.as_str(), "sensor_msgs/msg/PointCloud2"));
        }
        t
    }

    /// Publishes one frame on every topic that has a reader. Returns how many messages were
    /// written.
    pub fn publish(&mut self, capture_timestamp_ns: u64, p: &Planes) -> anyhow::Result<usize> {
        let header = || convert::header(capture_timestamp_ns, &self.options.frame_id);
        let mut written = 0;
        if self.depth.wanted() {
            let depth = convert::depth_image(p, self.options.depth_encoding, header());
            self.depth.write(depth)?;
            written += 1;
        }
        if self.color.wanted() {
            self.color.write(convert::rgb_image(p, header()))?;
            written += 1;
        }
        if self.confidence.wanted() {
            self.confidence
                .write(convert::confidence_image(p, header()))?;
            written += 1;
        }
        // `--intrinsics` overrides the header's; a frame with neither has no calibration.
        let k = match self.options.intrinsics {
            Some(k) => Some(CameraIntrinsics::pinhole(k.fx, k.fy, k.cx, k.cy)),
            None => p.intrinsics,
        };
        if let Some(k) = k {
            for info in [&self.depth_info, &self.color_info].into_iter().flatten() {
                if info.wanted() {
                    info.write(convert::camera_info(p.width, p.height, &k, header()))?;
                    written += 1;
                }
            }
            if let Some(points) = &self.points {
                if points.wanted() {
                    let size = (p.width as usize, p.height as usize);
                    let rays = match self.rays.take() {
                        Some(r) if *r.intrinsics() == k && r.size() == size => r,
                        _ => Rays::new(&k, size.0, size.1)
                            .with_context(|| format!("{}: the frame's intrinsics", points.name))?,
                    };
                    let cloud = convert::point_cloud(p, &rays, self.options.cloud_rgb, header());
                    self.rays = Some(rays);
                    points.write(cloud)?;
                    written += 1;
                }
            }
        }
        Ok(written)
    }
}
