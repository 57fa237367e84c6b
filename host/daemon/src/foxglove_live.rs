//! The live Foxglove WebSocket server (`nusense serve --foxglove`): the same channels as a recording, built by
//! the same encoders, served by the Foxglove SDK's own server, so that the Foxglove app shows the sensor live.

use std::net::SocketAddr;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

use foxglove::websocket::{ChannelView, Client, ServerListener};
use foxglove::{Context, PartialMetadata, RawChannel, WebSocketServer, WebSocketServerHandle};
use nusense_estimator::SensorConfig;
use tokio::sync::broadcast::error::RecvError;

use crate::pipeline::{PipelineHandle, PublishedReading};
use crate::record::messages;
use crate::record::{channel_table, encode_jpeg, Kind, CALIBRATION_TOPIC};

/// Quality of frames compressed for the live view when the source gave no JPEG.
const LIVE_JPEG_QUALITY: u8 = 85;

#[derive(Debug, thiserror::Error)]
pub enum FoxgloveLiveError {
    #[error("cannot start the Foxglove WebSocket server on {addr}: {source}")]
    Start {
        addr: SocketAddr,
        source: foxglove::FoxgloveError,
    },
    #[error("cannot create Foxglove channel {topic}: {source}")]
    Channel {
        topic: &'static str,
        source: foxglove::FoxgloveError,
    },
}

/// A running server; stops when dropped.
pub struct FoxgloveLive {
    /// The channels belong to this context and close with it, so it lives as long as the server.
    _context: Arc<Context>,
    server: Option<WebSocketServerHandle>,
    task: tokio::task::JoinHandle<()>,
    addr: SocketAddr,
}

impl FoxgloveLive {
    /// Starts serving on `addr` (port 0 picks one) and publishing every reading of `pipeline`.
    pub async fn start(
        pipeline: PipelineHandle,
        config: SensorConfig,
        addr: SocketAddr,
    ) -> Result<Self, FoxgloveLiveError> {
        let context = Context::new();
        let mut channels = Vec::new();
        for spec in channel_table() {
            let channel = context
                .channel_builder(spec.topic)
                .schema(spec.schema)
                .message_encoding(spec.message_encoding)
                .build_raw()
                .map_err(|source| FoxgloveLiveError::Channel {
                    topic: spec.topic,
                    source,
                })?;
            channels.push(channel);
        }
        let calibration_wanted = Arc::new(AtomicBool::new(true));
        let server = WebSocketServer::new()
            .name("nusense")
            .listener(Arc::new(CalibrationOnSubscribe(calibration_wanted.clone())))
            .bind(addr.ip().to_string(), addr.port())
            .context(&context)
            .start()
            .await
            .map_err(|source| FoxgloveLiveError::Start { addr, source })?;
        let bound = SocketAddr::new(addr.ip(), server.port());
        let readings = pipeline.subscribe();
        let task = tokio::spawn(publish(pipeline, config, channels, readings, calibration_wanted));
        Ok(Self {
            _context: context,
            server: Some(server),
            task,
            addr: bound,
        })
    }

    /// Where clients connect (`ws://ADDR`).
    pub fn addr(&self) -> SocketAddr {
        self.addr
    }
}

impl Drop for FoxgloveLive {
    fn drop(&mut self) {
        self.task.abort();
        if let Some(server) = self.server.take() {
            drop(server.stop());
        }
    }
}

/// The calibration changes only with the frame size, so it is sent then and whenever a client subscribes to it
/// (a client that connects late gets it with the next frame).
struct CalibrationOnSubscribe(Arc<AtomicBool>);

impl ServerListener for CalibrationOnSubscribe {
    fn on_subscribe(&self, _client: Client, channel: ChannelView<'_>) {
        if channel.topic() == CALIBRATION_TOPIC {
            self.0.store(true, Ordering::Relaxed);
        }
    }
}

async fn publish(
    pipeline: PipelineHandle,
    config: SensorConfig,
    channels: Vec<Arc<RawChannel>>,
    mut readings: tokio::sync::broadcast::Receiver<Arc<PublishedReading>>,
    calibration_wanted: Arc<AtomicBool>,
) {
    let log = |kind: Kind, data: &[u8], time_us: u64| {
        channels[kind as usize].log_with_meta(
            data,
            PartialMetadata {
                log_time: Some(time_us.saturating_mul(1000)),
            },
        );
    };
    let mut last_frame = None;
    let mut calibrated_size = None;
    loop {
        let published = match readings.recv().await {
            Ok(published) => published,
            // A slow server side skips readings rather than falling behind the sensor.
            Err(RecvError::Lagged(_)) => continue,
            Err(RecvError::Closed) => return,
        };
        if let Some(frame) = pipeline.latest_processed().filter(|f| Some(f.frame_id) != last_frame) {
            last_frame = Some(frame.frame_id);
            let capture_time_us = frame.reading.message.capture_time_us;
            let Ok((width, height)) = frame.pixels.dimensions() else {
                continue;
            };
            let resend = calibration_wanted.swap(false, Ordering::Relaxed);
            if resend || calibrated_size != Some((width, height)) {
                calibrated_size = Some((width, height));
                let calibration = messages::calibration(capture_time_us, &config, width, height);
                log(Kind::Calibration, &calibration, capture_time_us);
            }
            let jpeg = match frame.pixels.jpeg() {
                Some(jpeg) => jpeg.clone(),
                None => {
                    let pixels = frame.pixels.clone();
                    let encoded = tokio::task::spawn_blocking(move || {
                        pixels.to_rgb().map(|image| encode_jpeg(&image, LIVE_JPEG_QUALITY))
                    })
                    .await;
                    match encoded {
                        Ok(Ok(jpeg)) => Arc::new(jpeg),
                        _ => continue,
                    }
                }
            };
            log(Kind::Frame, &messages::frame(capture_time_us, &jpeg), capture_time_us);
        }
        let time_us = published.message.capture_time_us;
        if let Some(annotations) = messages::annotations(&published) {
            log(Kind::Annotations, &annotations, time_us);
        }
        log(Kind::Reading, &messages::reading(&published), time_us);
    }
}
