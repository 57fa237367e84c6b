//! `nusense bootloader`: restarts a board into the STM32's ROM DFU bootloader, the first step of flashing a board
//! that has no debug probe (then `dfu-util`, see firmware/README.md).

use std::process::ExitCode;

use nusense_protocol::{Reply, RequestBody};

use super::devices::BoardArgs;

#[derive(clap::Args)]
pub struct Args {
    #[command(flatten)]
    pub board: BoardArgs,
    /// Print the board's port and the flash commands as JSON.
    #[arg(long)]
    pub json: bool,
}

/// The flash that follows, in two pieces that leave the saved configuration (flash sectors 1-2) alone; vectors.bin
/// and code.bin are made with arm-none-eabi-objcopy as firmware/README.md ("First flash") shows. One image written
/// from 0x08000000 would erase the saved configuration.
const FLASH_COMMANDS: [&str; 2] = [
    "dfu-util -a 0 -s 0x08000000 -D vectors.bin",
    "dfu-util -a 0 -s 0x0800C000:leave -D code.bin",
];

pub fn run(args: Args) -> anyhow::Result<ExitCode> {
    let mut board = args.board.open()?;
    match board.link.request(RequestBody::EnterBootloader)? {
        Reply::Ack => {
            if args.json {
                let message = serde_json::json!({
                    "port": board.port,
                    "state": "restarting into the DFU bootloader",
                    "flash": FLASH_COMMANDS,
                });
                println!("{}", serde_json::to_string_pretty(&message)?);
            } else {
                println!(
                    "Board on {} is restarting into its DFU bootloader. Flash the image in two pieces, which leave \
                     the saved configuration (flash sectors 1-2) alone; vectors.bin and code.bin are made with \
                     arm-none-eabi-objcopy as firmware/README.md (\"First flash\") shows:\n  {}\n  {}\n\
                     (one image written from 0x08000000 would erase the saved configuration)",
                    board.port, FLASH_COMMANDS[0], FLASH_COMMANDS[1]
                );
            }
            Ok(ExitCode::SUCCESS)
        }
        other => anyhow::bail!("the board answered EnterBootloader with {other:?} instead of an acknowledgement"),
    }
}
