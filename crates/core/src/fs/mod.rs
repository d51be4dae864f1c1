//! Files: the one atomic writer ([`atomic`]: an output appears under its name only when
//! complete), read-only memory maps ([`mmap`]) and little-endian records ([`le`]).

pub mod atomic;
pub mod le;
pub mod mmap;
