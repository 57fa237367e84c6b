//! The virtual board in process: the host's link against the firmware core, without a pty.

use std::time::{Duration, Instant};

use nusense_protocol::{Channel, Side, PROTOCOL_VERSION};

use super::*;
use crate::{BoardLink, LinkOptions};

fn options() -> LinkOptions {
    LinkOptions {
        timeout: Duration::from_millis(200),
        retries: 2,
        baud: 115_200,
    }
}

fn open(board: &VirtualBoard) -> BoardLink {
    BoardLink::over(Box::new(board.connect().unwrap()), options()).unwrap()
}

/// Waits until `done` holds for the board's currents, up to `limit`; the currents at the end.
fn wait_currents(board: &VirtualBoard, limit: Duration, done: impl Fn([f32; 4]) -> bool) -> [f32; 4] {
    let deadline = Instant::now() + limit;
    loop {
        let currents = board.led_currents_ma();
        if done(currents) || Instant::now() >= deadline {
            return currents;
        }
        std::thread::sleep(Duration::from_millis(5));
    }
}

#[test]
fn the_firmware_core_answers_through_an_in_process_pipe() {
    let board = VirtualBoard::spawn_in_process().unwrap();
    let mut link = open(&board);
    let info = link.info().unwrap();
    assert_eq!(info.protocol_version, PROTOCOL_VERSION);
    assert_eq!(info.board_id.as_str(), "virtual-board");
    assert_eq!(info.mcu_uid, board.options.identity.mcu_uid);
    // The control loop runs whether or not the host talks.
    let before = board.control_steps();
    std::thread::sleep(Duration::from_millis(30));
    assert!(board.control_steps() > before);
}

#[test]
fn led_currents_follow_the_setpoint_and_go_dark_when_disabled() {
    let board = VirtualBoard::spawn_in_process().unwrap();
    // Boots lit at the nominal 100 mA.
    let boot = wait_currents(&board, Duration::from_secs(3), |c| {
        c.iter().all(|ma| (ma - 100.0).abs() < 3.0)
    });
    assert!(boot.iter().all(|ma| (ma - 100.0).abs() < 3.0), "{boot:?}");
    let mut link = open(&board);
    link.set_led(Channel::One(Side::Bottom), 60, true).unwrap();
    let lit = wait_currents(&board, Duration::from_secs(3), |c| {
        (c[Side::Bottom.index()] - 60.0).abs() < 3.0
    });
    assert!((lit[Side::Bottom.index()] - 60.0).abs() < 3.0, "{lit:?}");
    assert!((lit[Side::Top.index()] - 100.0).abs() < 3.0, "{lit:?}");
    link.set_led(Channel::One(Side::Bottom), 60, false).unwrap();
    let dark = wait_currents(&board, Duration::from_secs(3), |c| c[Side::Bottom.index()] < 1.0);
    assert!(dark[Side::Bottom.index()] < 1.0, "{dark:?}");
}

#[test]
fn a_new_connection_needs_a_new_handshake_and_gets_one() {
    let board = VirtualBoard::spawn_in_process().unwrap();
    let mut first = open(&board);
    first.set_led(Channel::All, 50, true).unwrap();
    drop(first);
    let mut second = open(&board);
    second.ping(5).unwrap();
    // The LEDs keep their state across host sessions.
    let status = second.status().unwrap();
    assert!(
        status
            .channels
            .iter()
            .all(|channel| channel.setpoint_ma == 50 && channel.enabled),
        "{status:?}"
    );
    assert!(board.host_sessions() >= 2);
}

#[test]
fn a_saved_configuration_survives_unplugging() {
    let mut board = VirtualBoard::spawn_in_process().unwrap();
    let mut link = open(&board);
    link.set_led(Channel::One(Side::Left), 70, true).unwrap();
    link.save_config().unwrap();
    link.set_led(Channel::One(Side::Left), 20, true).unwrap();
    board.unplug();
    assert!(link.ping(1).unwrap_err().is_disconnect());
    assert_eq!(board.led_currents_ma(), [0.0; 4]);
    board.replug().unwrap();
    let mut link = open(&board);
    let status = link.status().unwrap();
    assert_eq!(status.channels[Side::Left.index()].setpoint_ma, 70);
    assert!(status.channels[Side::Left.index()].enabled);
}

#[test]
fn an_injected_open_string_is_reported_as_a_fault() {
    let board = VirtualBoard::spawn_in_process().unwrap();
    let mut link = open(&board);
    link.set_led(Channel::One(Side::Top), 100, true).unwrap();
    board.set_string_fault(Side::Top, StringFault::Open);
    let deadline = Instant::now() + Duration::from_secs(3);
    loop {
        let status = link.status().unwrap();
        if status.channels[Side::Top.index()].faults.open_string {
            break;
        }
        assert!(Instant::now() < deadline, "no open-string fault: {status:?}");
        std::thread::sleep(Duration::from_millis(10));
    }
}

#[test]
fn a_pty_board_cannot_be_connected_in_process() {
    let board = VirtualBoard::spawn_pty().unwrap();
    assert!(board.path().starts_with("/dev/pts/"), "{}", board.path());
    assert!(matches!(board.connect(), Err(VirtualBoardError::NotInProcess)));
}
