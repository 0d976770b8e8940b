//! MAVLink 2 out (dialect `common`), over UDP or a serial port:
//!
//! | what | message |
//! |---|---|
//! | alive, every `1 / heartbeat_hz` s | `HEARTBEAT` (type `MAV_TYPE_ONBOARD_CONTROLLER`, autopilot `MAV_AUTOPILOT_INVALID`, state `MAV_STATE_ACTIVE`) |
//! | each sign detection the navigator read (up to 4 per frame) | `DEBUG_VECT`: `name` = sign (`left`, `right`, `stop`, `wait`, `class<N>`), `x` = box centre offset from the image centre / image width, `y` = distance from the box height (m), `z` = score; `time_usec` = frame time |
//! | turn left / right | `COMMAND_LONG` `MAV_CMD_CONDITION_YAW`: 90°, `yaw_rate_deg` °/s, direction −1 (left) / 1 (right), relative |
//! | land (STOP) | `COMMAND_LONG` `MAV_CMD_NAV_LAND` (here: all positions NaN) |
//! | hold (WAIT) / resume | `COMMAND_LONG` `MAV_CMD_DO_PAUSE_CONTINUE`: 0 = hold, 1 = continue |
//!
//! Commands go to `target_system` / `target_component`; messages carry `system_id` /
//! `component_id` (the configuration's `[mavlink]` table).
//!
//! In (`--mavlink-odometry`): `LOCAL_POSITION_NED` and `ATTITUDE` from the autopilot,
//! read without blocking before every decision ([`Link::poll`], [`crate::odometry`]).
use crate::config::MavlinkConfig;
use crate::odometry::MavOdometry;
use frugal_nav::NavCommand;
use mavlink::dialects::common::{
    COMMAND_LONG_DATA, DEBUG_VECT_DATA, HEARTBEAT_DATA, MavAutopilot, MavCmd, MavMessage,
    MavModeFlag, MavState, MavType,
};
use mavlink::error::MessageReadError;
use mavlink::{MavConnection, MavHeader, MavlinkVersion};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU8, AtomicU64, Ordering};
use std::time::Duration;

/// A MAVLink link that cannot be opened or written.
#[derive(Debug, thiserror::Error)]
#[error("MAVLink {address}: {message}")]
pub struct LinkError {
    /// The address given (`udpout:HOST:PORT`, `serial:DEVICE:BAUD`, …).
    pub address: String,
    /// What went wrong.
    pub message: String,
}

type Conn = mavlink::Connection<MavMessage>;

/// The open link, with a thread sending HEARTBEATs.
pub struct Link {
    conn: Arc<Conn>,
    address: String,
    ids: MavlinkConfig,
    yaw_rate_deg: f32,
    sequence: Arc<AtomicU8>,
    stop: Arc<AtomicBool>,
    heartbeat: Option<std::thread::JoinHandle<()>>,
    /// Commands sent.
    pub commands: u64,
    /// Heartbeats sent (shared with the thread).
    heartbeats: Arc<AtomicU64>,
}

fn header(ids: &MavlinkConfig, sequence: &AtomicU8) -> MavHeader {
    MavHeader {
        system_id: u32::from(ids.system_id),
        component_id: ids.component_id,
        sequence: sequence.fetch_add(1, Ordering::Relaxed),
    }
}

fn heartbeat() -> MavMessage {
    MavMessage::HEARTBEAT(HEARTBEAT_DATA {
        custom_mode: 0,
        mavtype: MavType::MAV_TYPE_ONBOARD_CONTROLLER,
        autopilot: MavAutopilot::MAV_AUTOPILOT_INVALID,
        base_mode: MavModeFlag::empty(),
        system_status: MavState::MAV_STATE_ACTIVE,
        mavlink_version: 3,
    })
}

impl Link {
    /// Open `address` (the `mavlink` crate's syntax: `udpout:127.0.0.1:14550`,
    /// `udpin:0.0.0.0:14550`, `serial:/dev/ttyAMA0:921600`) and start the heartbeat.
    pub fn open(address: &str, ids: &MavlinkConfig, yaw_rate_deg: f64) -> Result<Self, LinkError> {
        let err = |message: String| LinkError {
            address: address.to_owned(),
            message,
        };
        let mut conn: Conn =
            mavlink::connect::<MavMessage>(address).map_err(|e| err(e.to_string()))?;
        conn.set_protocol_version(MavlinkVersion::V2);
        let conn = Arc::new(conn);
        let sequence = Arc::new(AtomicU8::new(0));
        let stop = Arc::new(AtomicBool::new(false));
        let heartbeats = Arc::new(AtomicU64::new(0));
        let period = Duration::from_secs_f64(1.0 / ids.heartbeat_hz);
        let thread = {
            let (conn, sequence, stop, heartbeats, ids) = (
                Arc::clone(&conn),
                Arc::clone(&sequence),
                Arc::clone(&stop),
                Arc::clone(&heartbeats),
                ids.clone(),
            );
            std::thread::spawn(move || {
                while !stop.load(Ordering::Relaxed) {
                    if conn.send(&header(&ids, &sequence), &heartbeat()).is_ok() {
                        heartbeats.fetch_add(1, Ordering::Relaxed);
                    }
                    let until = std::time::Instant::now() + period;
                    while !stop.load(Ordering::Relaxed) && std::time::Instant::now() < until {
                        std::thread::sleep(Duration::from_millis(10));
                    }
                }
            })
        };
        Ok(Self {
            conn,
            address: address.to_owned(),
            ids: ids.clone(),
            yaw_rate_deg: yaw_rate_deg as f32,
            sequence,
            stop,
            heartbeat: Some(thread),
            commands: 0,
            heartbeats,
        })
    }

    fn send(&self, msg: &MavMessage) -> Result<(), LinkError> {
        self.conn
            .send(&header(&self.ids, &self.sequence), msg)
            .map(|_| ())
            .map_err(|e| LinkError {
                address: self.address.clone(),
                message: e.to_string(),
            })
    }

    /// A detection as `DEBUG_VECT` (see the module documentation).
    pub fn detection(
        &self,
        time_usec: u64,
        name: &str,
        offset: f32,
        distance_m: f32,
        score: f32,
    ) -> Result<(), LinkError> {
        let mut label = [0u8; 10];
        for (d, s) in label.iter_mut().zip(name.bytes()) {
            *d = s;
        }
        self.send(&MavMessage::DEBUG_VECT(DEBUG_VECT_DATA {
            time_usec,
            x: offset,
            y: distance_m,
            z: score,
            name: label.into(),
        }))
    }

    /// The `COMMAND_LONG` for `command`.
    pub fn command_message(&self, command: NavCommand) -> MavMessage {
        let (cmd, params) = match command {
            NavCommand::TurnLeft | NavCommand::TurnRight => (
                MavCmd::MAV_CMD_CONDITION_YAW,
                [
                    90.0,
                    self.yaw_rate_deg,
                    if command == NavCommand::TurnLeft {
                        -1.0
                    } else {
                        1.0
                    },
                    1.0,
                    0.0,
                    0.0,
                    0.0,
                ],
            ),
            NavCommand::Land => (
                MavCmd::MAV_CMD_NAV_LAND,
                [0.0, 0.0, 0.0, f32::NAN, f32::NAN, f32::NAN, f32::NAN],
            ),
            NavCommand::Hold => (MavCmd::MAV_CMD_DO_PAUSE_CONTINUE, [0.0; 7]),
            NavCommand::Resume => (
                MavCmd::MAV_CMD_DO_PAUSE_CONTINUE,
                [1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
            ),
        };
        MavMessage::COMMAND_LONG(COMMAND_LONG_DATA {
            param1: params[0],
            param2: params[1],
            param3: params[2],
            param4: params[3],
            param5: params[4],
            param6: params[5],
            param7: params[6],
            command: cmd,
            target_system: self.ids.target_system,
            target_component: self.ids.target_component,
            confirmation: 0,
        })
    }

    /// Send `command`.
    pub fn command(&mut self, command: NavCommand) -> Result<(), LinkError> {
        self.send(&self.command_message(command))?;
        self.commands += 1;
        Ok(())
    }

    /// Read every message waiting on the link without blocking (a serial port waits up
    /// to its 1 ms timeout), feeding positions and attitudes to `odometry`. Messages
    /// that do not parse are skipped; returns how many messages were read.
    pub fn poll(&self, odometry: &mut MavOdometry) -> Result<u64, LinkError> {
        let mut read = 0;
        loop {
            match self.conn.try_recv() {
                Ok((_, msg)) => {
                    read += 1;
                    match msg {
                        MavMessage::LOCAL_POSITION_NED(p) => {
                            odometry.position(f64::from(p.x), f64::from(p.y));
                        }
                        MavMessage::ATTITUDE(a) => odometry.attitude(f64::from(a.yaw)),
                        _ => {}
                    }
                }
                Err(MessageReadError::Io(e))
                    if matches!(
                        e.kind(),
                        std::io::ErrorKind::WouldBlock
                            | std::io::ErrorKind::TimedOut
                            // no ground station or autopilot listening yet (UDP)
                            | std::io::ErrorKind::ConnectionRefused
                    ) =>
                {
                    return Ok(read);
                }
                Err(MessageReadError::Parse(_)) => {}
                Err(MessageReadError::Io(e)) => {
                    return Err(LinkError {
                        address: self.address.clone(),
                        message: format!("reading: {e}"),
                    });
                }
            }
        }
    }

    /// Heartbeats sent so far.
    pub fn heartbeats(&self) -> u64 {
        self.heartbeats.load(Ordering::Relaxed)
    }
}

impl Drop for Link {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(t) = self.heartbeat.take() {
            let _ = t.join();
        }
    }
}
