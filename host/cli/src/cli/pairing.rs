//! Several real sensors in one daemon: each `--sensor camera=CAMERA,board=BOARD` pairs one camera with one LED
//! board, each named by its device path or its USB serial number (or frames replayed from a folder or recording,
//! `replay=PATH`, instead of a camera). Matching them against the devices attached is hardware-free (the lists
//! come from the caller) so that every way it can go wrong is tested here.

use std::fmt;
use std::path::PathBuf;
use std::str::FromStr;

/// How a `--sensor` names a device: a path (`/dev/video2`, `/dev/ttyACM1`, `/dev/serial/by-id/...`) or a USB
/// serial number.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum DeviceName {
    Path(String),
    Serial(String),
}

impl DeviceName {
    fn parse(text: &str) -> Self {
        match text.starts_with('/') {
            true => DeviceName::Path(text.to_owned()),
            false => DeviceName::Serial(text.to_owned()),
        }
    }
}

impl fmt::Display for DeviceName {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            DeviceName::Path(path) => write!(f, "{path}"),
            DeviceName::Serial(serial) => write!(f, "with USB serial number {serial}"),
        }
    }
}

/// Where a sensor's frames come from.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Frames {
    Camera(DeviceName),
    /// A folder of images or an `.mcap` recording.
    Replay(PathBuf),
}

/// One `--sensor` argument: the camera (or replay) and the LED board of one sensor.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct SensorSpec {
    pub frames: Frames,
    pub board: DeviceName,
}

impl FromStr for SensorSpec {
    type Err = String;

    /// `camera=CAMERA,board=BOARD` (or `replay=PATH,board=BOARD`), in any order.
    fn from_str(text: &str) -> Result<Self, Self::Err> {
        let (mut frames, mut board) = (None, None);
        for part in text.split(',') {
            let (key, value) = part
                .split_once('=')
                .ok_or_else(|| format!("`{part}` is not KEY=VALUE (expected camera=DEVICE,board=DEVICE)"))?;
            let (key, value) = (key.trim(), value.trim());
            if value.is_empty() {
                return Err(format!("`{key}` is empty"));
            }
            let (slot, parsed) = match key {
                "camera" => (&mut frames, Some(Frames::Camera(DeviceName::parse(value)))),
                "replay" => (&mut frames, Some(Frames::Replay(PathBuf::from(value)))),
                "board" => {
                    if board.replace(DeviceName::parse(value)).is_some() {
                        return Err("`board` is given twice".into());
                    }
                    continue;
                }
                other => return Err(format!("unknown key `{other}` (expected camera or replay, and board)")),
            };
            if std::mem::replace(slot, parsed).is_some() {
                return Err("one camera or one replay per sensor".into());
            }
        }
        Ok(SensorSpec {
            frames: frames.ok_or("no camera= (a V4L2 device path or the camera's USB serial number) or replay=")?,
            board: board.ok_or("no board= (a serial device path or the board's USB serial number)")?,
        })
    }
}

/// A device as the system lists it: a camera's V4L2 node or a board's serial port, with its USB serial number.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Device {
    pub path: String,
    pub serial: Option<String>,
}

/// One sensor's devices, resolved.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct SensorPair {
    /// The camera as the user named it (a serial number stays one: the camera resolves it to its capture node
    /// when it opens, and again when it comes back), spelt as the camera reports it; or the replay.
    pub frames: Frames,
    /// The board's serial device.
    pub board_path: String,
    /// The board's USB serial number when the system lists it: the sensor's name.
    pub board_serial: Option<String>,
}

#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum PairingError {
    #[error("--sensor {sensor}: no {kind} {name} is attached (attached: {attached})")]
    NotFound {
        sensor: usize,
        kind: &'static str,
        name: DeviceName,
        attached: String,
    },
    #[error("--sensor {sensor}: several {kind}s have USB serial number {serial} ({paths}); name one by its path")]
    Ambiguous {
        sensor: usize,
        kind: &'static str,
        serial: String,
        paths: String,
    },
    #[error("--sensor {first} and --sensor {second} both use the {kind} {device}: each sensor needs its own")]
    Shared {
        first: usize,
        second: usize,
        kind: &'static str,
        device: String,
    },
}

/// Pairs each spec's camera and board with the attached devices. Sensors are numbered from 1 in errors, in the
/// order given. A board named by serial must be attached; one named by path is taken as it is (a board that is
/// unplugged now is waited for, as `--board` does). Two sensors may not share a camera or a board, however each
/// names it.
pub fn pair(specs: &[SensorSpec], cameras: &[Device], boards: &[Device]) -> Result<Vec<SensorPair>, PairingError> {
    let mut pairs = Vec::with_capacity(specs.len());
    // Each sensor's camera and board as one identity each: the USB serial when known, else the path.
    let mut taken: Vec<(Option<String>, String)> = Vec::with_capacity(specs.len());
    for (index, spec) in specs.iter().enumerate() {
        let sensor = index + 1;
        let (frames, camera_identity) = match &spec.frames {
            Frames::Camera(name) => {
                let camera = resolve(sensor, "camera", name, cameras, true)?;
                let identity = camera.serial.clone().unwrap_or_else(|| canonical(&camera.path));
                let frames = match (name, camera.serial) {
                    // As the camera spells it: opening it compares serials exactly.
                    (DeviceName::Serial(_), Some(serial)) => Frames::Camera(DeviceName::Serial(serial)),
                    (name, _) => Frames::Camera(name.clone()),
                };
                (frames, Some(identity))
            }
            // Replaying one recording for two sensors takes nothing from either.
            Frames::Replay(path) => (Frames::Replay(path.clone()), None),
        };
        let board = resolve(sensor, "board", &spec.board, boards, false)?;
        let board_identity = board.serial.clone().unwrap_or_else(|| canonical(&board.path));
        for (other, (other_camera, other_board)) in taken.iter().enumerate() {
            let shared = |kind, device: String| PairingError::Shared {
                first: other + 1,
                second: sensor,
                kind,
                device,
            };
            if let (Some(camera), Frames::Camera(name)) = (&camera_identity, &spec.frames) {
                if other_camera.as_ref() == Some(camera) {
                    return Err(shared("camera", name.to_string()));
                }
            }
            if *other_board == board_identity {
                return Err(shared("board", spec.board.to_string()));
            }
        }
        taken.push((camera_identity, board_identity));
        pairs.push(SensorPair {
            frames,
            board_path: board.path,
            board_serial: board.serial,
        });
    }
    Ok(pairs)
}

/// The attached device a name means. `grouped`: one device may list several paths under one serial (a UVC
/// camera's capture and metadata nodes), so a serial shared by several paths is one device, not an ambiguity.
fn resolve(
    sensor: usize,
    kind: &'static str,
    name: &DeviceName,
    attached: &[Device],
    grouped: bool,
) -> Result<Device, PairingError> {
    match name {
        DeviceName::Path(path) => {
            // A link (`/dev/serial/by-id/...`, `/dev/v4l/by-id/...`) names the device it points to, so it is
            // compared by its target. The path stays as given: a by-id link survives the replug that can move
            // the device to another `ttyACM` number.
            let target = canonical(path);
            let serial = attached
                .iter()
                .find(|d| d.path == *path || canonical(&d.path) == target)
                .and_then(|d| d.serial.clone());
            Ok(Device {
                path: path.clone(),
                serial,
            })
        }
        DeviceName::Serial(serial) => {
            // USB serial numbers are hex more often than not; people type them in either case.
            let matching: Vec<&Device> = attached
                .iter()
                .filter(|d| d.serial.as_deref().is_some_and(|s| s.eq_ignore_ascii_case(serial)))
                .collect();
            match matching.as_slice() {
                [] => Err(PairingError::NotFound {
                    sensor,
                    kind,
                    name: name.clone(),
                    attached: describe(attached),
                }),
                [one, ..] if grouped || matching.len() == 1 => Ok((*one).clone()),
                several => Err(PairingError::Ambiguous {
                    sensor,
                    kind,
                    serial: serial.clone(),
                    paths: several.iter().map(|d| d.path.as_str()).collect::<Vec<_>>().join(", "),
                }),
            }
        }
    }
}

/// The path with every symbolic link resolved, or as given when it does not resolve (a device unplugged now, a
/// dangling by-id link): two names of one device are then one identity.
fn canonical(path: &str) -> String {
    std::fs::canonicalize(path).map_or_else(|_| path.to_owned(), |target| target.display().to_string())
}

fn describe(devices: &[Device]) -> String {
    if devices.is_empty() {
        return "none".to_owned();
    }
    devices
        .iter()
        .map(|d| match &d.serial {
            Some(serial) => format!("{} ({serial})", d.path),
            None => d.path.clone(),
        })
        .collect::<Vec<_>>()
        .join(", ")
}

#[cfg(test)]
mod tests {
    use super::*;

    fn device(path: &str, serial: Option<&str>) -> Device {
        Device {
            path: path.to_owned(),
            serial: serial.map(str::to_owned),
        }
    }

    fn spec(text: &str) -> SensorSpec {
        text.parse().unwrap()
    }

    /// Two UVC cameras (a capture and a metadata node each) and two boards.
    fn attached() -> (Vec<Device>, Vec<Device>) {
        let cameras = vec![
            device("/dev/video0", Some("CAM-A")),
            device("/dev/video1", Some("CAM-A")),
            device("/dev/video2", Some("CAM-B")),
            device("/dev/video3", Some("CAM-B")),
        ];
        let boards = vec![
            device("/dev/ttyACM0", Some("3F0042001151333137383932")),
            device("/dev/ttyACM1", Some("2A0031000D51333137383932")),
        ];
        (cameras, boards)
    }

    #[test]
    fn a_spec_takes_camera_and_board_in_either_order_by_path_or_serial() {
        assert_eq!(
            spec("camera=/dev/video2,board=3F0042001151333137383932"),
            SensorSpec {
                frames: Frames::Camera(DeviceName::Path("/dev/video2".into())),
                board: DeviceName::Serial("3F0042001151333137383932".into()),
            }
        );
        assert_eq!(
            spec(" board = /dev/ttyACM0 , camera = CAM-A "),
            SensorSpec {
                frames: Frames::Camera(DeviceName::Serial("CAM-A".into())),
                board: DeviceName::Path("/dev/ttyACM0".into()),
            }
        );
        assert_eq!(
            spec("replay=runs/pressing.mcap,board=/dev/pts/4"),
            SensorSpec {
                frames: Frames::Replay("runs/pressing.mcap".into()),
                board: DeviceName::Path("/dev/pts/4".into()),
            }
        );
    }

    #[test]
    fn a_malformed_spec_says_what_is_wrong() {
        let error = |text: &str| text.parse::<SensorSpec>().unwrap_err();
        assert_eq!(
            error("camera=/dev/video0"),
            "no board= (a serial device path or the board's USB serial number)"
        );
        assert_eq!(
            error("board=/dev/ttyACM0"),
            "no camera= (a V4L2 device path or the camera's USB serial number) or replay="
        );
        assert_eq!(error("camera=/dev/video0,board="), "`board` is empty");
        assert_eq!(
            error("camera=/dev/video0,camera=/dev/video2,board=X"),
            "one camera or one replay per sensor"
        );
        assert_eq!(
            error("camera=/dev/video0,replay=run.mcap,board=X"),
            "one camera or one replay per sensor"
        );
        assert_eq!(error("camera=/dev/video0,board=X,board=Y"), "`board` is given twice");
        assert_eq!(
            error("camera=/dev/video0,led=X"),
            "unknown key `led` (expected camera or replay, and board)"
        );
        assert_eq!(
            error("/dev/video0"),
            "`/dev/video0` is not KEY=VALUE (expected camera=DEVICE,board=DEVICE)"
        );
    }

    #[test]
    fn each_sensor_gets_its_own_camera_and_board_whichever_way_they_are_named() {
        let (cameras, boards) = attached();
        let pairs = pair(
            &[
                spec("camera=cam-b,board=3f0042001151333137383932"),
                spec("camera=/dev/video0,board=/dev/ttyACM1"),
            ],
            &cameras,
            &boards,
        )
        .unwrap();
        assert_eq!(
            pairs,
            vec![
                SensorPair {
                    frames: Frames::Camera(DeviceName::Serial("CAM-B".into())),
                    board_path: "/dev/ttyACM0".into(),
                    board_serial: Some("3F0042001151333137383932".into()),
                },
                SensorPair {
                    frames: Frames::Camera(DeviceName::Path("/dev/video0".into())),
                    board_path: "/dev/ttyACM1".into(),
                    board_serial: Some("2A0031000D51333137383932".into()),
                },
            ]
        );
    }

    #[test]
    fn two_sensors_may_replay_one_recording_but_not_share_its_board() {
        let (cameras, boards) = attached();
        let pairs = pair(
            &[
                spec("replay=run.mcap,board=/dev/pts/3"),
                spec("replay=run.mcap,board=/dev/pts/4"),
            ],
            &cameras,
            &boards,
        )
        .unwrap();
        assert_eq!(pairs[1].frames, Frames::Replay("run.mcap".into()));
        assert_eq!(pairs[1].board_path, "/dev/pts/4");
        assert_eq!(
            pair(
                &[spec("replay=a,board=/dev/pts/3"), spec("replay=b,board=/dev/pts/3")],
                &cameras,
                &boards
            )
            .unwrap_err()
            .to_string(),
            "--sensor 1 and --sensor 2 both use the board /dev/pts/3: each sensor needs its own"
        );
    }

    #[test]
    fn a_board_named_by_a_path_not_attached_now_is_taken_as_given() {
        let (cameras, boards) = attached();
        let pairs = pair(&[spec("camera=/dev/video0,board=/dev/ttyACM7")], &cameras, &boards).unwrap();
        assert_eq!(pairs[0].board_path, "/dev/ttyACM7");
        assert_eq!(pairs[0].board_serial, None);
    }

    #[test]
    fn a_device_named_by_a_serial_nobody_has_is_not_found_with_what_is_attached() {
        let (cameras, boards) = attached();
        assert_eq!(
            pair(&[spec("camera=CAM-C,board=/dev/ttyACM0")], &cameras, &boards),
            Err(PairingError::NotFound {
                sensor: 1,
                kind: "camera",
                name: DeviceName::Serial("CAM-C".into()),
                attached: "/dev/video0 (CAM-A), /dev/video1 (CAM-A), /dev/video2 (CAM-B), /dev/video3 (CAM-B)".into(),
            })
        );
        let error = pair(
            &[spec("camera=CAM-A,board=/dev/ttyACM0"), spec("camera=CAM-B,board=FFFF")],
            &cameras,
            &boards,
        )
        .unwrap_err();
        assert_eq!(
            error.to_string(),
            "--sensor 2: no board with USB serial number FFFF is attached (attached: /dev/ttyACM0 \
             (3F0042001151333137383932), /dev/ttyACM1 (2A0031000D51333137383932))"
        );
        assert_eq!(
            pair(&[spec("camera=CAM-A,board=FFFF")], &cameras, &[])
                .unwrap_err()
                .to_string(),
            "--sensor 1: no board with USB serial number FFFF is attached (attached: none)"
        );
    }

    #[test]
    fn two_sensors_sharing_a_camera_or_a_board_are_refused_however_each_names_it() {
        let (cameras, boards) = attached();
        // The same camera by its metadata node's path and by its serial.
        assert_eq!(
            pair(
                &[
                    spec("camera=/dev/video1,board=/dev/ttyACM0"),
                    spec("camera=cam-a,board=/dev/ttyACM1")
                ],
                &cameras,
                &boards
            ),
            Err(PairingError::Shared {
                first: 1,
                second: 2,
                kind: "camera",
                device: "with USB serial number cam-a".into(),
            })
        );
        // The same board by path and by serial.
        let error = pair(
            &[
                spec("camera=CAM-A,board=2A0031000D51333137383932"),
                spec("camera=CAM-B,board=/dev/ttyACM0"),
                spec("camera=/dev/video9,board=/dev/ttyACM1"),
            ],
            &cameras,
            &boards,
        )
        .unwrap_err();
        assert_eq!(
            error.to_string(),
            "--sensor 1 and --sensor 3 both use the board /dev/ttyACM1: each sensor needs its own"
        );
        // Two boards given by the same path that is not attached now.
        assert!(matches!(
            pair(
                &[
                    spec("camera=CAM-A,board=/dev/ttyUSB0"),
                    spec("camera=CAM-B,board=/dev/ttyUSB0")
                ],
                &cameras,
                &boards
            ),
            Err(PairingError::Shared {
                first: 1,
                second: 2,
                kind: "board",
                ..
            })
        ));
    }

    /// `/dev/serial/by-id/...` beside `/dev/ttyACM0`, in a temporary folder: a link and the node it points to.
    struct LinkedNode {
        _folder: tempfile::TempDir,
        node: String,
        link: String,
    }

    fn linked_node() -> LinkedNode {
        let folder = tempfile::tempdir().unwrap();
        let node = folder.path().join("ttyACM0");
        std::fs::write(&node, b"").unwrap();
        let by_id = folder.path().join("serial").join("by-id");
        std::fs::create_dir_all(&by_id).unwrap();
        let link = by_id.join("usb-NUSense_LED_board_3F0042001151333137383932-if00");
        std::os::unix::fs::symlink("../../ttyACM0", &link).unwrap();
        LinkedNode {
            node: node.display().to_string(),
            link: link.display().to_string(),
            _folder: folder,
        }
    }

    #[test]
    fn a_board_named_by_its_by_id_link_is_the_board_it_points_to() {
        let devices = linked_node();
        let cameras = attached().0;
        let boards = vec![
            device(&devices.node, Some("3F0042001151333137383932")),
            device("/dev/ttyACM1", Some("2A0031000D51333137383932")),
        ];
        let used_twice = |first: &str, second: &str| {
            pair(
                &[
                    spec(&format!("camera=CAM-A,board={first}")),
                    spec(&format!("camera=CAM-B,board={second}")),
                ],
                &cameras,
                &boards,
            )
        };
        let refused = |second: &str| {
            Err(PairingError::Shared {
                first: 1,
                second: 2,
                kind: "board",
                device: second.to_owned(),
            })
        };
        // The link, then the node it points to by path, and by serial.
        assert_eq!(used_twice(&devices.link, &devices.node), refused(&devices.node));
        assert_eq!(
            used_twice(&devices.link, "3f0042001151333137383932"),
            refused("with USB serial number 3f0042001151333137383932")
        );
        assert_eq!(used_twice(&devices.node, &devices.link), refused(&devices.link));
        // The link is kept as given (it outlives a replug) and its board's serial found.
        let pairs = used_twice(&devices.link, "/dev/ttyACM1").unwrap();
        assert_eq!(pairs[0].board_path, devices.link);
        assert_eq!(pairs[0].board_serial.as_deref(), Some("3F0042001151333137383932"));
    }

    #[test]
    fn a_link_and_its_target_are_one_board_even_when_the_board_is_not_listed() {
        let devices = linked_node();
        let (cameras, boards) = attached();
        assert_eq!(
            pair(
                &[
                    spec(&format!("camera=CAM-A,board={}", devices.node)),
                    spec(&format!("camera=CAM-B,board={}", devices.link)),
                ],
                &cameras,
                &boards
            ),
            Err(PairingError::Shared {
                first: 1,
                second: 2,
                kind: "board",
                device: devices.link.clone(),
            })
        );
    }

    #[test]
    fn two_boards_with_one_serial_are_ambiguous_and_must_be_named_by_path() {
        let cameras = attached().0;
        let boards = vec![
            device("/dev/ttyACM0", Some("0BAD")),
            device("/dev/ttyACM1", Some("0BAD")),
        ];
        assert_eq!(
            pair(&[spec("camera=CAM-A,board=0bad")], &cameras, &boards),
            Err(PairingError::Ambiguous {
                sensor: 1,
                kind: "board",
                serial: "0bad".into(),
                paths: "/dev/ttyACM0, /dev/ttyACM1".into(),
            })
        );
        assert_eq!(
            pair(&[spec("camera=CAM-A,board=/dev/ttyACM1")], &cameras, &boards).unwrap()[0].board_path,
            "/dev/ttyACM1"
        );
    }
}
