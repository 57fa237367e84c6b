//! Finding boards by their USB identity.

use serde::Serialize;

use super::error::LinkError;

/// USB vendor id of the board (pid.codes, open-source hardware).
pub const USB_VID: u16 = 0x1209;
/// USB product id of the NUSense LED board.
pub const USB_PID: u16 = 0x4E55;

/// A board's serial device as the operating system lists it.
#[derive(Clone, Debug, PartialEq, Eq, Serialize)]
pub struct BoardPort {
    /// Device path to pass to [`super::BoardLink::open`], e.g. /dev/ttyACM0.
    pub path: String,
    /// USB serial number: hex of the MCU's unique id.
    pub serial_number: Option<String>,
    pub manufacturer: Option<String>,
    pub product: Option<String>,
}

/// Every attached board (USB VID:PID 1209:4E55), sorted by path.
pub fn discover() -> Result<Vec<BoardPort>, LinkError> {
    let ports = serialport::available_ports().map_err(LinkError::Discover)?;
    let mut boards = boards_among(ports);
    boards.sort_by(|a, b| a.path.cmp(&b.path));
    Ok(boards)
}

/// The one board to talk to: the one with `serial_number` if given, else the only one attached.
pub fn find_board(serial_number: Option<&str>) -> Result<BoardPort, LinkError> {
    choose_board(discover()?, serial_number)
}

fn boards_among(ports: Vec<serialport::SerialPortInfo>) -> Vec<BoardPort> {
    ports
        .into_iter()
        .filter_map(|port| match port.port_type {
            serialport::SerialPortType::UsbPort(usb) if usb.vid == USB_VID && usb.pid == USB_PID => Some(BoardPort {
                path: port.port_name,
                serial_number: usb.serial_number,
                manufacturer: usb.manufacturer,
                product: usb.product,
            }),
            _ => None,
        })
        .collect()
}

fn choose_board(boards: Vec<BoardPort>, serial_number: Option<&str>) -> Result<BoardPort, LinkError> {
    let mut matching: Vec<BoardPort> = boards
        .into_iter()
        .filter(|board| match serial_number {
            // USB serial numbers are hex; people type them in either case.
            Some(wanted) => board
                .serial_number
                .as_deref()
                .is_some_and(|serial| serial.eq_ignore_ascii_case(wanted)),
            None => true,
        })
        .collect();
    match matching.len() {
        0 => Err(LinkError::NoBoardFound {
            vid: USB_VID,
            pid: USB_PID,
            serial_number: serial_number.map(str::to_owned),
        }),
        1 => Ok(matching.remove(0)),
        count => Err(LinkError::SeveralBoards {
            count,
            ports: matching
                .iter()
                .map(|board| board.path.as_str())
                .collect::<Vec<_>>()
                .join(", "),
        }),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use serialport::{SerialPortInfo, SerialPortType, UsbPortInfo};

    fn usb(path: &str, vid: u16, pid: u16, serial: &str) -> SerialPortInfo {
        SerialPortInfo {
            port_name: path.to_owned(),
            port_type: SerialPortType::UsbPort(UsbPortInfo {
                vid,
                pid,
                serial_number: Some(serial.to_owned()),
                manufacturer: None,
                product: Some("NUSense LED board".to_owned()),
            }),
        }
    }

    #[test]
    fn only_ports_with_the_board_vid_and_pid_are_boards() {
        let ports = vec![
            usb("/dev/ttyACM0", USB_VID, USB_PID, "0011AABB"),
            usb("/dev/ttyACM1", 0x0483, 0x5740, "STLINK"),
            usb("/dev/ttyACM2", USB_VID, 0x0001, "OTHER"),
            SerialPortInfo {
                port_name: "/dev/ttyS0".into(),
                port_type: SerialPortType::Unknown,
            },
        ];
        let boards = boards_among(ports);
        assert_eq!(boards.len(), 1);
        assert_eq!(boards[0].path, "/dev/ttyACM0");
        assert_eq!(boards[0].serial_number.as_deref(), Some("0011AABB"));
    }

    #[test]
    fn a_board_is_chosen_by_serial_number_in_any_case() {
        let boards = boards_among(vec![
            usb("/dev/ttyACM0", USB_VID, USB_PID, "0011AABB"),
            usb("/dev/ttyACM3", USB_VID, USB_PID, "CAFE0001"),
        ]);
        assert_eq!(
            choose_board(boards.clone(), Some("cafe0001")).unwrap().path,
            "/dev/ttyACM3"
        );
        let several = choose_board(boards.clone(), None).unwrap_err();
        assert!(
            matches!(several, LinkError::SeveralBoards { count: 2, .. }),
            "{several}"
        );
        let missing = choose_board(boards, Some("DEAD")).unwrap_err();
        assert!(missing.to_string().contains("serial number DEAD"), "{missing}");
    }
}
