//! `nusense devices`: attached LED boards (by USB VID:PID) and cameras. Also the board selection shared by
//! `nusense info` and `nusense led` (`--port PATH | --serial S | --virtual`).

use std::process::ExitCode;

use nusense_board::virtual_board::VirtualBoard;
use nusense_board::{BoardLink, BoardPort, LinkOptions};
use nusense_capture::{list_cameras, CameraInfo};
use serde::Serialize;

#[derive(clap::Args)]
pub struct Args {
    /// Print JSON instead of a table.
    #[arg(long)]
    pub json: bool,
}

#[derive(Serialize)]
struct Listing {
    boards: Vec<BoardPort>,
    cameras: Vec<CameraInfo>,
}

pub fn run(args: Args) -> anyhow::Result<ExitCode> {
    let listing = Listing {
        boards: nusense_board::discover()?,
        cameras: list_cameras(),
    };
    if args.json {
        println!("{}", serde_json::to_string_pretty(&listing)?);
        return Ok(ExitCode::SUCCESS);
    }
    println!(
        "Boards (USB {:04x}:{:04x}):",
        nusense_board::USB_VID,
        nusense_board::USB_PID
    );
    if listing.boards.is_empty() {
        println!("  none (nusense info --virtual / nusense serve run on a virtual board)");
    }
    for board in &listing.boards {
        println!(
            "  {:<20} serial {:<26} {}",
            board.path,
            board.serial_number.as_deref().unwrap_or("-"),
            board.product.as_deref().unwrap_or("")
        );
    }
    println!("Cameras (V4L2):");
    if listing.cameras.is_empty() {
        println!("  none");
    }
    for camera in &listing.cameras {
        println!(
            "  {:<20} serial {:<26} {}",
            camera.path,
            camera.usb_serial.as_deref().unwrap_or("-"),
            camera.name
        );
    }
    Ok(ExitCode::SUCCESS)
}

/// Which board a command talks to.
#[derive(clap::Args, Debug)]
pub struct BoardArgs {
    /// Serial device of the board (e.g. /dev/ttyACM0, /dev/serial/by-id/..., a pty).
    #[arg(long, value_name = "PATH", conflicts_with_all = ["serial", "virtual_board"])]
    pub port: Option<String>,
    /// The attached board with this USB serial number.
    #[arg(long, value_name = "SERIAL", conflicts_with = "virtual_board")]
    pub serial: Option<String>,
    /// A virtual board (the firmware logic on a simulated LED plant behind a pty), started for this command.
    #[arg(long = "virtual")]
    pub virtual_board: bool,
    /// Reply timeout per attempt, in milliseconds.
    #[arg(long, value_name = "MS", default_value_t = 250)]
    pub timeout_ms: u64,
}

/// An open link, and the virtual board behind it when there is one (it must outlive the link).
pub struct OpenBoard {
    pub link: BoardLink,
    pub port: String,
    pub virtual_board: Option<VirtualBoard>,
}

impl BoardArgs {
    /// Opens the chosen board, the only attached one when none was named.
    pub fn open(&self) -> anyhow::Result<OpenBoard> {
        let options = LinkOptions {
            timeout: std::time::Duration::from_millis(self.timeout_ms),
            ..LinkOptions::default()
        };
        let (port, virtual_board) = if self.virtual_board {
            let board = VirtualBoard::spawn_pty()?;
            (board.path().to_owned(), Some(board))
        } else if let Some(port) = &self.port {
            (port.clone(), None)
        } else {
            (nusense_board::find_board(self.serial.as_deref())?.path, None)
        };
        let link = BoardLink::open(&port, options)?;
        Ok(OpenBoard {
            link,
            port,
            virtual_board,
        })
    }
}
