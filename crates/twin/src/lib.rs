//! gyrobench's digital twin of the RL-16 on its bench, the geometry it
//! turns in, and the TOML configuration checking every gyrobench file
//! shares (`config::Checker`: errors that name the file, line, key and the
//! fix). The modules keep the paths the controller gives them
//! (`gyrobench::twin`, `gyrobench::geometry`, `gyrobench::config`).

pub mod config;
pub mod geometry;
pub mod procedures;
pub mod twin;
