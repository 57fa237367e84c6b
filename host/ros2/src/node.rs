//! The DDS glue: one ROS 2 node per sensor, three publishers, and a thread that publishes every reading of the
//! pipeline. What the messages hold is decided in `messages`; this file only moves them.

use std::net::{IpAddr, Ipv4Addr};
use std::sync::Arc;
use std::thread::JoinHandle;

use nusense_daemon::pipeline::{PipelineHandle, PublishedReading};
use nusense_daemon::record::encode_jpeg;
use ros2_client::dds::rustdds::DomainParticipantBuilder;
use ros2_client::dds::{Context, Node, Publisher};
use ros2_client::qos::{Durability, History, Reliability, WhenFull};
use ros2_client::{MessageTypeName, Name, NodeName, NodeOptions, QosProfile};
use serde::Serialize;
use tokio::sync::broadcast::error::RecvError;
use tokio::sync::oneshot;

use crate::messages::{self, CompressedImage, PointCloud2, WrenchStamped};
use crate::settings::{DiscoveryRange, Ros2Settings};

/// Quality of frames compressed for ROS when the source gave no JPEG (the simulator).
const JPEG_QUALITY: u8 = 85;

/// Samples each publisher keeps for late retransmission to a reliable subscriber.
const HISTORY_DEPTH: usize = 5;

/// REP 2003: a sensor driver publishes reliable and volatile ("system default"), so that reliable subscribers
/// (ROS's default) and best-effort ones (`SensorDataQoS`, what sensor consumers should use) both match. A reliable
/// publisher whose send window is full waits at most this long, then drops the sample rather than stall the
/// sensor.
const QOS: QosProfile = QosProfile::publisher_default()
    .reliability(Reliability::Reliable {
        when_full: WhenFull::Wait(std::time::Duration::from_millis(20)),
    })
    .durability(Durability::Volatile)
    .history(History::KeepLast { depth: HISTORY_DEPTH });

#[derive(Debug, thiserror::Error)]
pub enum Ros2Error {
    #[error("cannot join DDS domain {domain_id}: {source}")]
    Participant {
        domain_id: u16,
        source: ros2_client::dds::rustdds::dds::CreateError,
    },
    #[error("cannot create the ROS 2 context: {0}")]
    Context(ros2_client::CreateError),
    #[error("cannot create ROS 2 node {name}: {source}")]
    Node {
        name: String,
        source: ros2_client::dds::NodeCreateError,
    },
    #[error("{topic:?} is not a valid ROS 2 topic name")]
    Name { topic: String },
    #[error("cannot create ROS 2 topic {topic}: {source}")]
    Topic {
        topic: String,
        source: ros2_client::CreateError,
    },
    #[error("cannot start the ROS 2 publishing thread: {0}")]
    Thread(std::io::Error),
}

/// The topics one sensor publishes, as ROS names them.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Topics {
    /// `/nusense/<sensor>`
    pub namespace: String,
    /// `geometry_msgs/msg/WrenchStamped`
    pub wrench: String,
    /// `sensor_msgs/msg/CompressedImage` (image_transport's `compressed` under the `image` base topic)
    pub image: String,
    /// `sensor_msgs/msg/PointCloud2`, one point per contact
    pub contacts: String,
    /// The frame every message is stamped with.
    pub frame_id: String,
}

impl Topics {
    /// The names for a sensor token (see [`crate::sensor_token`]).
    pub fn for_sensor(token: &str) -> Self {
        let namespace = format!("/nusense/{token}");
        Self {
            wrench: format!("{namespace}/wrench"),
            image: format!("{namespace}/image/compressed"),
            contacts: format!("{namespace}/contacts"),
            frame_id: messages::frame_id(token),
            namespace,
        }
    }
}

/// The node of one sensor, publishing while it lives.
pub struct Ros2Out {
    topics: Topics,
    settings: Ros2Settings,
    stop: Option<oneshot::Sender<()>>,
    thread: Option<JoinHandle<()>>,
}

impl Ros2Out {
    /// Joins the DDS domain and starts publishing every reading of `pipeline` under `/nusense/<token>`.
    pub fn start(pipeline: PipelineHandle, token: &str, settings: Ros2Settings) -> Result<Self, Ros2Error> {
        let topics = Topics::for_sensor(token);
        let mut builder = DomainParticipantBuilder::new(settings.domain_id);
        if settings.range == DiscoveryRange::Localhost {
            builder = builder.with_only_networks([IpAddr::V4(Ipv4Addr::LOCALHOST)]);
        }
        let participant = builder.build().map_err(|source| Ros2Error::Participant {
            domain_id: settings.domain_id,
            source,
        })?;
        let context = Context::from_domain_participant(participant).map_err(Ros2Error::Context)?;
        let node_name = NodeName::new(&topics.namespace, "daemon").map_err(|_| Ros2Error::Name {
            topic: topics.namespace.clone(),
        })?;
        let mut node = context
            .new_node(node_name, NodeOptions::new().enable_rosout(false))
            .map_err(|source| Ros2Error::Node {
                name: format!("{}/daemon", topics.namespace),
                source,
            })?;
        let publishers = Publishers {
            wrench: publisher(&mut node, &topics.wrench, "geometry_msgs", "WrenchStamped")?,
            image: publisher(&mut node, &topics.image, "sensor_msgs", "CompressedImage")?,
            contacts: publisher(&mut node, &topics.contacts, "sensor_msgs", "PointCloud2")?,
        };
        let (stop, stopped) = oneshot::channel();
        let readings = pipeline.subscribe();
        let frame_id = topics.frame_id.clone();
        let thread = std::thread::Builder::new()
            .name("ros2-publish".into())
            .spawn(move || run(context, node, publishers, pipeline, readings, frame_id, stopped))
            .map_err(Ros2Error::Thread)?;
        Ok(Self {
            topics,
            settings,
            stop: Some(stop),
            thread: Some(thread),
        })
    }

    pub fn topics(&self) -> &Topics {
        &self.topics
    }

    pub fn settings(&self) -> &Ros2Settings {
        &self.settings
    }
}

impl Drop for Ros2Out {
    fn drop(&mut self) {
        if let Some(stop) = self.stop.take() {
            let _ = stop.send(());
        }
        // The thread stops at once (a publish waits at most the QoS's send-window wait), leaving the domain cleanly.
        if let Some(thread) = self.thread.take() {
            let _ = thread.join();
        }
    }
}

fn publisher<M: Serialize>(
    node: &mut Node,
    topic: &str,
    package: &str,
    type_name: &str,
) -> Result<Publisher<M>, Ros2Error> {
    let name = Name::parse(topic).map_err(|_| Ros2Error::Name {
        topic: topic.to_owned(),
    })?;
    let topic_error = |source| Ros2Error::Topic {
        topic: topic.to_owned(),
        source,
    };
    let dds_topic = node
        .create_topic(&name, MessageTypeName::new(package, type_name), &QOS)
        .map_err(topic_error)?;
    node.create_publisher(&dds_topic, None).map_err(topic_error)
}

struct Publishers {
    wrench: Publisher<WrenchStamped>,
    image: Publisher<CompressedImage>,
    contacts: Publisher<PointCloud2>,
}

/// The publishing thread: its own single-threaded runtime runs the node's spinner (ROS graph bookkeeping, so that
/// the node knows its subscribers) beside the loop over readings, until told to stop or the pipeline ends.
fn run(
    context: Context,
    mut node: Node,
    publishers: Publishers,
    pipeline: PipelineHandle,
    readings: tokio::sync::broadcast::Receiver<Arc<PublishedReading>>,
    frame_id: String,
    stopped: oneshot::Receiver<()>,
) {
    let runtime = match tokio::runtime::Builder::new_current_thread().enable_all().build() {
        Ok(runtime) => runtime,
        Err(error) => {
            tracing::error!("ROS 2: cannot start the publishing runtime: {error}");
            return;
        }
    };
    let spinner = node
        .spinner()
        .map_err(|e| tracing::warn!("ROS 2: no graph spinner: {e}"))
        .ok();
    runtime.block_on(async {
        let spin = async {
            if let Some(spinner) = spinner {
                if let Err(error) = spinner.spin().await {
                    tracing::warn!("ROS 2: graph spinner stopped: {error}");
                }
            }
            std::future::pending::<()>().await
        };
        tokio::select! {
            _ = stopped => {}
            _ = spin => {}
            _ = publish(&node, &publishers, &pipeline, readings, &frame_id) => {}
        }
    });
    drop(publishers);
    drop(node);
    drop(context);
}

async fn publish(
    node: &Node,
    publishers: &Publishers,
    pipeline: &PipelineHandle,
    mut readings: tokio::sync::broadcast::Receiver<Arc<PublishedReading>>,
    frame_id: &str,
) {
    let mut last_frame = None;
    loop {
        let published = match readings.recv().await {
            Ok(published) => published,
            // A slow network skips readings rather than falling behind the sensor.
            Err(RecvError::Lagged(_)) => continue,
            Err(RecvError::Closed) => return,
        };
        let reading = &published.message;
        if let Some(wrench) = messages::wrench(reading, frame_id) {
            if let Err(error) = publishers.wrench.publish(wrench) {
                tracing::debug!("ROS 2: wrench of frame {} not sent: {error}", reading.frame_id);
            }
        }
        if let Some(contacts) = messages::contacts(reading, frame_id) {
            if let Err(error) = publishers.contacts.publish(contacts) {
                tracing::debug!("ROS 2: contacts of frame {} not sent: {error}", reading.frame_id);
            }
        }
        // Frames are large: sent (and, from the simulator, compressed) only while someone subscribes.
        if publishers.image.get_subscription_count(node) == 0 {
            continue;
        }
        let Some(frame) = pipeline.latest_processed().filter(|f| Some(f.frame_id) != last_frame) else {
            continue;
        };
        last_frame = Some(frame.frame_id);
        let jpeg = match frame.pixels.jpeg() {
            Some(jpeg) => jpeg.clone(),
            None => match frame.pixels.to_rgb() {
                Ok(image) => Arc::new(encode_jpeg(&image, JPEG_QUALITY)),
                Err(_) => continue,
            },
        };
        let image = messages::compressed_image(jpeg, frame.reading.message.capture_time_us, frame_id);
        if let Err(error) = publishers.image.publish(image) {
            tracing::debug!("ROS 2: frame {} not sent: {error}", frame.frame_id);
        }
    }
}
