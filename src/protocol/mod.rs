//! Wire protocols, sans-IO: bytes in, events out. No sockets, no files,
//! no time here; drivers and simulators wrap these codecs.

pub mod frame;
