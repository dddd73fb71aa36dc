//! Wire protocols, sans-IO: bytes in, events out. No sockets, no files,
//! no time here; drivers and simulators wrap these codecs.

pub mod acl;
pub mod espec;
pub mod frame;
pub mod watlow;
