//! The parameters of a whole flight ([`FlightConfig`]): the navigator's
//! ([`NavConfig`], shared with the drone-side program), the camera and the on-board
//! computer.
use crate::perception::DeviceProfile;
use crate::render::CameraSpec;
pub use frugal_nav::NavConfig;

/// Everything a flight needs besides the maze and the perception.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct FlightConfig {
    /// The camera.
    pub camera: CameraSpec,
    /// Navigation parameters.
    pub nav: NavConfig,
    /// The on-board computer.
    pub device: DeviceProfile,
}

impl Default for FlightConfig {
    fn default() -> Self {
        Self {
            camera: CameraSpec::default(),
            nav: NavConfig::default(),
            device: DeviceProfile::tx2_like(),
        }
    }
}
