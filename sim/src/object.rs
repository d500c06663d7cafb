//! Cell contents: one compact byte per cell, and MiniGrid's 3-channel code.
//!
//! The grid stores an [`Object`] code per cell (`Object as u8`). Colours are
//! fixed per object kind (a single key/door colour, as in the paper's mazes),
//! so one byte carries MiniGrid's (object, colour, state) triple without loss;
//! [`Object::minigrid`] expands it.

use serde::{Deserialize, Serialize};

/// What occupies a cell. The discriminant is the byte stored in the grid.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
#[repr(u8)]
pub enum Object {
    /// Empty floor the agent can walk on.
    Floor = 0,
    /// Impassable wall.
    Wall = 1,
    /// A ball: collected by stepping on it in the MultiGoal tasks, picked up otherwise.
    Ball = 2,
    /// The key that unlocks locked doors.
    Key = 3,
    /// An open door: passable.
    DoorOpen = 4,
    /// A closed, unlocked door: `toggle` opens it.
    DoorClosed = 5,
    /// A locked door: `toggle` while carrying the key unlocks and opens it.
    DoorLocked = 6,
    /// The exit: stepping on it ends the episode.
    Exit = 7,
    /// Lava: stepping on it ends the episode (MultiGoal-Stochastic: −0.5).
    Lava = 8,
}

/// Number of distinct cell codes.
pub const NUM_OBJECTS: usize = 9;

/// MiniGrid's `OBJECT_TO_IDX` for the kinds we use.
pub mod minigrid_idx {
    /// `empty`
    pub const EMPTY: u8 = 1;
    /// `wall`
    pub const WALL: u8 = 2;
    /// `door`
    pub const DOOR: u8 = 4;
    /// `key`
    pub const KEY: u8 = 5;
    /// `ball`
    pub const BALL: u8 = 6;
    /// `goal`
    pub const GOAL: u8 = 8;
    /// `lava`
    pub const LAVA: u8 = 9;
    /// `agent`
    pub const AGENT: u8 = 10;
}

/// MiniGrid's `COLOR_TO_IDX`.
pub mod minigrid_color {
    /// red
    pub const RED: u8 = 0;
    /// green
    pub const GREEN: u8 = 1;
    /// blue
    pub const BLUE: u8 = 2;
    /// yellow
    pub const YELLOW: u8 = 4;
    /// grey
    pub const GREY: u8 = 5;
}

impl Object {
    /// Every object, in code order.
    pub const ALL: [Object; NUM_OBJECTS] = [
        Object::Floor,
        Object::Wall,
        Object::Ball,
        Object::Key,
        Object::DoorOpen,
        Object::DoorClosed,
        Object::DoorLocked,
        Object::Exit,
        Object::Lava,
    ];

    /// The object with this cell code, if any.
    #[inline]
    pub fn from_code(code: u8) -> Option<Object> {
        Self::ALL.get(code as usize).copied()
    }

    /// The layout-file character of this object.
    pub fn to_char(self) -> char {
        match self {
            Object::Floor => '.',
            Object::Wall => '#',
            Object::Ball => 'B',
            Object::Key => 'K',
            Object::DoorOpen => 'O',
            Object::DoorClosed => 'C',
            Object::DoorLocked => 'D',
            Object::Exit => 'E',
            Object::Lava => 'L',
        }
    }

    /// The object a layout-file character stands for (agent characters excluded).
    pub fn from_char(c: char) -> Option<Object> {
        Some(match c {
            '.' => Object::Floor,
            '#' => Object::Wall,
            'B' => Object::Ball,
            'K' => Object::Key,
            'O' => Object::DoorOpen,
            'C' => Object::DoorClosed,
            'D' => Object::DoorLocked,
            'E' => Object::Exit,
            'L' => Object::Lava,
            _ => return None,
        })
    }

    /// A lower-case name, as used in traces (`"key"`, `"door_locked"`, ...).
    pub fn name(self) -> &'static str {
        match self {
            Object::Floor => "floor",
            Object::Wall => "wall",
            Object::Ball => "ball",
            Object::Key => "key",
            Object::DoorOpen => "door_open",
            Object::DoorClosed => "door_closed",
            Object::DoorLocked => "door_locked",
            Object::Exit => "exit",
            Object::Lava => "lava",
        }
    }

    /// True for the three door states.
    #[inline]
    pub fn is_door(self) -> bool {
        matches!(
            self,
            Object::DoorOpen | Object::DoorClosed | Object::DoorLocked
        )
    }

    /// A task object the agent changes by acting on it rather than by
    /// stepping onto it: a key (pickup) or a door that is not open
    /// (toggle). Such a cell is reached as a goal when the agent's action
    /// changes it (Door-Key's object goals, `learner::hrl::worker`).
    #[inline]
    pub fn is_acted_on(self) -> bool {
        matches!(self, Object::Key | Object::DoorClosed | Object::DoorLocked)
    }

    /// MiniGrid's `can_overlap`: the agent may stand on it (balls are
    /// collected on contact in MultiGoal tasks, see `env`).
    #[inline]
    pub fn can_overlap(self) -> bool {
        matches!(
            self,
            Object::Floor | Object::DoorOpen | Object::Exit | Object::Lava
        )
    }

    /// MiniGrid's `can_pickup`.
    #[inline]
    pub fn can_pickup(self) -> bool {
        matches!(self, Object::Key | Object::Ball)
    }

    /// MiniGrid's 3-channel `(object, colour, state)` encoding of this cell.
    pub fn minigrid(self) -> [u8; 3] {
        use minigrid_color::*;
        use minigrid_idx::*;
        match self {
            Object::Floor => [EMPTY, 0, 0],
            Object::Wall => [WALL, GREY, 0],
            Object::Ball => [BALL, BLUE, 0],
            Object::Key => [KEY, YELLOW, 0],
            Object::DoorOpen => [DOOR, YELLOW, 0],
            Object::DoorClosed => [DOOR, YELLOW, 1],
            Object::DoorLocked => [DOOR, YELLOW, 2],
            Object::Exit => [GOAL, GREEN, 0],
            Object::Lava => [LAVA, RED, 0],
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn codes_and_chars_round_trip() {
        for o in Object::ALL {
            assert_eq!(Object::from_code(o as u8), Some(o));
            assert_eq!(Object::from_char(o.to_char()), Some(o));
        }
        assert_eq!(Object::from_code(NUM_OBJECTS as u8), None);
        assert_eq!(Object::from_char('x'), None);
    }

    #[test]
    fn minigrid_codes_distinguish_every_object() {
        let mut seen = std::collections::HashSet::new();
        for o in Object::ALL {
            assert!(seen.insert(o.minigrid()), "{o:?} collides");
        }
        assert_eq!(Object::DoorLocked.minigrid(), [4, 4, 2]);
    }
}
