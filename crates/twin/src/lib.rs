//! gyrobench's digital twin of the RL-16 on its bench. The geometry it
//! turns in and the configuration checking it reads its file with are the
//! vocabulary crate's (`gyrobench-model`).

pub mod twin;
