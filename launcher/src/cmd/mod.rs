//! One module per command (or family of commands), each owning its clap
//! arguments and its code; `main` routes the parsed command line to them.
//! Two modules serve several commands: [`shm_space`] (the free-space check on
//! `/dev/shm`) and [`bench`] (running a program beside `nerve` in its place:
//! `nerve bench`, and through [`demo`] `nerve demo` and `nerve calibrate`).

pub mod bench;
pub mod bridge;
pub mod bridge_keys;
pub mod call;
pub mod demo;
pub mod down;
pub mod drive;
pub mod echo;
pub mod export;
pub mod foxglove;
pub mod inspect;
pub mod iox2;
pub mod launch;
pub mod logs;
pub mod mem;
pub mod new;
pub mod plot;
pub mod publish;
pub mod record;
pub mod replay;
pub mod shm_space;
pub mod snapshot;
pub mod start;
pub mod types;
pub mod ui;
pub mod wire;
