//! A bench for the core: a Controller wired to the simulated LED plant, stepped at a fixed control rate, with a
//! host side that speaks the protocol through the real framing.
#![allow(dead_code)]

use nusense_firmware_core::plant::{LedPlant, PlantParams};
use nusense_firmware_core::{Action, BoardConfig, Controller, Identity, Measurements, PowerState};
use nusense_protocol::framing::{encode, FrameDecoder, MAX_FRAME_LEN};
use nusense_protocol::{BoardMessage, Reply, Request, RequestBody, Response, Telemetry, PROTOCOL_VERSION};

/// Control period of the bench: the slowest rate the firmware is allowed to run its loop at (1 kHz).
pub const STEP_US: u64 = 1_000;

pub struct Bench {
    pub controller: Controller,
    pub plant: LedPlant,
    pub now_us: u64,
    pub last: Measurements,
    seq: u16,
    host: FrameDecoder,
    pub responses: Vec<Response>,
    pub telemetry: Vec<Telemetry>,
    pub actions: Vec<Action>,
}

pub fn identity() -> Identity {
    Identity::new("0.1.0", "abcdef012345", "nusense-test", [7; 12])
}

impl Bench {
    pub fn new() -> Self {
        Self::with(BoardConfig::default(), PlantParams::default())
    }

    /// A board that booted with `config` on a configured USB port.
    pub fn with(config: BoardConfig, params: PlantParams) -> Self {
        Self::around_with(Controller::new(identity(), config), params)
    }

    pub fn around(controller: Controller) -> Self {
        Self::around_with(controller, PlantParams::default())
    }

    fn around_with(mut controller: Controller, params: PlantParams) -> Self {
        controller.set_power_state(PowerState::Configured);
        Self {
            controller,
            plant: LedPlant::new(params, 42),
            now_us: 0,
            last: Measurements::default(),
            seq: 0,
            host: FrameDecoder::new(),
            responses: Vec::new(),
            telemetry: Vec::new(),
            actions: Vec::new(),
        }
    }

    /// A bench that has done the handshake.
    pub fn connected() -> Self {
        let mut bench = Self::new();
        bench.handshake();
        bench
    }

    pub fn handshake(&mut self) {
        let hello = self.request(RequestBody::Hello {
            protocol_version: PROTOCOL_VERSION,
        });
        assert!(
            matches!(
                hello.result,
                Ok(Reply::Hello {
                    protocol_version: PROTOCOL_VERSION,
                    ..
                })
            ),
            "{hello:?}"
        );
    }

    /// One control period: the plant runs with the duty of the previous step, then the controller sees the result.
    pub fn step(&mut self) -> [f32; 4] {
        let duty = self.controller.duty();
        self.last = self.plant.step(duty, STEP_US as u32);
        self.now_us += STEP_US;
        let duty = self.controller.control_step(self.now_us, &self.last);
        let mut out = Vec::new();
        self.controller
            .poll_telemetry(self.now_us, &mut |frame: &[u8]| out.extend_from_slice(frame));
        self.receive(&out);
        duty
    }

    pub fn run_ms(&mut self, ms: u64) {
        for _ in 0..ms * 1_000 / STEP_US {
            self.step();
        }
    }

    /// Sends raw bytes to the board and collects whatever it answers.
    pub fn send_bytes(&mut self, bytes: &[u8]) {
        let mut out = Vec::new();
        self.controller
            .on_rx(bytes, self.now_us, &mut |frame: &[u8]| out.extend_from_slice(frame));
        self.receive(&out);
        while let Some(action) = self.controller.take_action() {
            self.actions.push(action);
        }
    }

    fn receive(&mut self, bytes: &[u8]) {
        let mut messages = Vec::new();
        self.host
            .feed::<BoardMessage>(bytes, |m| messages.push(m.expect("the board sends only valid frames")));
        for m in messages {
            match m {
                BoardMessage::Response(r) => self.responses.push(r),
                BoardMessage::Telemetry(t) => self.telemetry.push(t),
            }
        }
    }

    pub fn next_seq(&mut self) -> u16 {
        self.seq = self.seq.wrapping_add(1);
        self.seq
    }

    /// Sends one request and returns the board's answer to it (panics if there is none: every request that reaches
    /// the board intact must be answered, except SaveConfig, which waits for the flash).
    pub fn request(&mut self, body: RequestBody) -> Response {
        let seq = self.next_seq();
        self.send(&Request { seq, body });
        let response = self.responses.pop().expect("an answer to every request");
        assert_eq!(response.seq, seq, "the answer carries the request's sequence number");
        response
    }

    pub fn send<T: serde::Serialize>(&mut self, message: &T) {
        let mut buf = [0u8; MAX_FRAME_LEN];
        let frame = encode(message, &mut buf).expect("encodable").to_vec();
        self.send_bytes(&frame);
    }

    pub fn true_current_ma(&self) -> [f32; 4] {
        self.plant.true_current_ma()
    }
}
