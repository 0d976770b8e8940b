//! The sign classes: ten procedurally drawn signs modelled on Belgian / European road
//! sign codes, four of which carry a navigation meaning the drone acts on.
use crate::ClassId;
use serde::{Deserialize, Serialize};

/// What the drone does when it sees a sign.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum NavAction {
    /// Turn left at the next junction.
    TurnLeft,
    /// Turn right at the next junction.
    TurnRight,
    /// Stop and land / hold.
    Stop,
    /// Wait (pedestrians may cross).
    Wait,
}

impl NavAction {
    /// Every action.
    pub const ALL: [NavAction; 4] = [
        NavAction::TurnLeft,
        NavAction::TurnRight,
        NavAction::Stop,
        NavAction::Wait,
    ];

    /// `turn_left`, `turn_right`, `stop` or `wait`.
    pub fn name(self) -> &'static str {
        match self {
            NavAction::TurnLeft => "turn_left",
            NavAction::TurnRight => "turn_right",
            NavAction::Stop => "stop",
            NavAction::Wait => "wait",
        }
    }

    /// The action with this name (case-insensitive).
    pub fn from_name(name: &str) -> Option<NavAction> {
        NavAction::ALL
            .into_iter()
            .find(|a| a.name().eq_ignore_ascii_case(name.trim()))
    }
}

/// One class of the dataset, as stored in the manifest.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ClassInfo {
    /// Index into the class list (COCO `category_id` is `id + 1`).
    pub id: ClassId,
    /// Short snake_case name, e.g. `turn_left`.
    pub name: String,
    /// The road sign code it is modelled on, e.g. `D1a` (empty for imported classes).
    #[serde(default, skip_serializing_if = "String::is_empty")]
    pub code: String,
    /// The navigation meaning, if the drone acts on this sign.
    pub action: Option<NavAction>,
}

/// The ten built-in sign classes, in class-id order.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
#[non_exhaustive]
pub enum Sign {
    /// D1a-style blue disc with a white arrow pointing left.
    TurnLeft,
    /// D1a-style blue disc with a white arrow pointing right.
    TurnRight,
    /// B5 red octagon with white "STOP".
    Stop,
    /// Blue square, white triangle, black walking person (pedestrians: wait).
    Wait,
    /// A14 red-bordered warning triangle with "!".
    A14,
    /// E1 no parking: blue disc, red ring and slash.
    E1,
    /// C1 no entry: red disc with a white bar.
    C1,
    /// C43 speed limit: white disc, red ring, "30".
    C43,
    /// C31R no right turn: white disc, red ring, black right-turn arrow, red slash.
    C31R,
    /// C21 weight limit: white disc, red ring, "5t".
    C21,
}

impl Sign {
    /// Every sign, in class-id order.
    pub const ALL: [Sign; 10] = [
        Sign::TurnLeft,
        Sign::TurnRight,
        Sign::Stop,
        Sign::Wait,
        Sign::A14,
        Sign::E1,
        Sign::C1,
        Sign::C43,
        Sign::C31R,
        Sign::C21,
    ];

    /// The class id (index into [`Sign::ALL`] and into [`classes`]).
    pub fn id(self) -> ClassId {
        Sign::ALL.iter().position(|s| *s == self).unwrap_or(0) as ClassId
    }

    /// The sign with this class id.
    pub fn from_id(id: ClassId) -> Option<Sign> {
        Sign::ALL.get(usize::from(id)).copied()
    }

    /// The sign with this name or code (case-insensitive), e.g. `stop`, `B5`, `c31r`.
    pub fn from_name(name: &str) -> Option<Sign> {
        let name = name.trim();
        Sign::ALL
            .into_iter()
            .find(|s| s.name().eq_ignore_ascii_case(name) || s.code().eq_ignore_ascii_case(name))
    }

    /// Short snake_case name.
    pub fn name(self) -> &'static str {
        match self {
            Sign::TurnLeft => "turn_left",
            Sign::TurnRight => "turn_right",
            Sign::Stop => "stop",
            Sign::Wait => "wait",
            Sign::A14 => "danger",
            Sign::E1 => "no_parking",
            Sign::C1 => "no_entry",
            Sign::C43 => "speed_limit_30",
            Sign::C31R => "no_right_turn",
            Sign::C21 => "weight_limit_5t",
        }
    }

    /// The road sign code it is modelled on.
    pub fn code(self) -> &'static str {
        match self {
            Sign::TurnLeft => "D1a-L",
            Sign::TurnRight => "D1a-R",
            Sign::Stop => "B5",
            Sign::Wait => "F49",
            Sign::A14 => "A14",
            Sign::E1 => "E1",
            Sign::C1 => "C1",
            Sign::C43 => "C43",
            Sign::C31R => "C31R",
            Sign::C21 => "C21",
        }
    }

    /// The navigation meaning, if any.
    pub fn action(self) -> Option<NavAction> {
        match self {
            Sign::TurnLeft => Some(NavAction::TurnLeft),
            Sign::TurnRight => Some(NavAction::TurnRight),
            Sign::Stop => Some(NavAction::Stop),
            Sign::Wait => Some(NavAction::Wait),
            _ => None,
        }
    }

    /// The manifest entry for this sign.
    pub fn info(self) -> ClassInfo {
        ClassInfo {
            id: self.id(),
            name: self.name().to_owned(),
            code: self.code().to_owned(),
            action: self.action(),
        }
    }
}

/// The built-in class list, in class-id order.
pub fn classes() -> Vec<ClassInfo> {
    Sign::ALL.into_iter().map(Sign::info).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ids_names_and_codes_round_trip() {
        for (i, s) in Sign::ALL.into_iter().enumerate() {
            assert_eq!(usize::from(s.id()), i);
            assert_eq!(Sign::from_id(s.id()), Some(s));
            assert_eq!(Sign::from_name(s.name()), Some(s));
            assert_eq!(Sign::from_name(&s.code().to_lowercase()), Some(s));
        }
        assert_eq!(Sign::from_id(10), None);
        assert_eq!(Sign::from_name("yield"), None);
        let actions: Vec<_> = classes().iter().filter_map(|c| c.action).collect();
        assert_eq!(
            actions,
            [
                NavAction::TurnLeft,
                NavAction::TurnRight,
                NavAction::Stop,
                NavAction::Wait
            ]
        );
    }
}
