//! `volcapd` as a library: the daemon's modules, used by its binary, its integration tests
//! and the fuzz targets.

pub mod capture;
pub mod compute;
pub mod config;
pub mod dbus;
pub mod http;
pub mod netguard;
pub mod notify;
pub mod pipeline;
pub mod placeholder;
pub mod rtsp;
