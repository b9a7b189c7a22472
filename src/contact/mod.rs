//! Contact physics: the contact law, its history store, and wall contacts.

pub mod history;

pub use history::{ContactHistory, ContactKey, ContactState, WALL_BIT};
