//! `volcap status`, `volcap set-view`, ...: talk to a running volcapd over its D-Bus
//! interface `org.volcap.Capture1` (the same one busctl and other tools use).

use anyhow::{Context, Result, bail};
use clap::{Args, Subcommand};
use std::path::PathBuf;

#[derive(Args, Debug, Clone)]
pub struct BusArgs {
    /// Use the system bus (production; the default is the session bus).
    #[arg(long, conflicts_with = "address")]
    pub system: bool,
    /// A bus address, e.g. unix:path=/run/dbus/system_bus_socket.
    #[arg(long)]
    pub address: Option<String>,
}

#[derive(Subcommand, Debug)]
pub enum CtlCmd {
    /// Health: every property of the daemon.
    Status {
        #[command(flatten)]
        bus: BusArgs,
        /// One JSON object instead of the table.
        #[arg(long)]
        json: bool,
    },
    /// Orbit the render view.
    SetView {
        #[command(flatten)]
        bus: BusArgs,
        /// Degrees about the vertical axis.
        #[arg(long, allow_hyphen_values = true)]
        yaw: f64,
        /// Degrees up (+) or down (-), |pitch| <= 80.
        #[arg(long, default_value_t = 0.0, allow_hyphen_values = true)]
        pitch: f64,
        /// Metres from the look-at point; 0 keeps the camera's own.
        #[arg(long, default_value_t = 0.0)]
        distance: f64,
    },
    /// Grid level 5..=9 (resolution 33 .. 513).
    SetResolution {
        #[command(flatten)]
        bus: BusArgs,
        level: u32,
    },
    /// Stop rendering (the camera keeps running).
    Pause {
        #[command(flatten)]
        bus: BusArgs,
    },
    Resume {
        #[command(flatten)]
        bus: BusArgs,
    },
    /// Re-read the daemon's config file.
    Reload {
        #[command(flatten)]
        bus: BusArgs,
    },
    /// Save the current frame as PNG.
    Snapshot {
        #[command(flatten)]
        bus: BusArgs,
        #[arg(long, default_value = "snapshot.png")]
        out: PathBuf,
    },
}

#[zbus::proxy(
    interface = "org.volcap.Capture1",
    default_service = "org.volcap.Capture1",
    default_path = "/org/volcap/Capture1"
)]
trait Capture1 {
    fn set_view(&self, yaw: f64, pitch: f64, distance: f64) -> zbus::Result<()>;
    fn set_resolution(&self, level: u32) -> zbus::Result<()>;
    fn pause(&self) -> zbus::Result<()>;
    fn resume(&self) -> zbus::Result<()>;
    fn reload(&self) -> zbus::Result<String>;
    fn snapshot(&self) -> zbus::Result<Vec<u8>>;
}

/// Connect to the bus `bus` names. A failure says which bus and address were tried, the
/// cause once, and how to choose another.
async fn connect(bus: &BusArgs) -> Result<zbus::Connection> {
    let session_address = || {
        std::env::var("DBUS_SESSION_BUS_ADDRESS").unwrap_or_else(|_| {
            let dir = std::env::var("XDG_RUNTIME_DIR")
                .unwrap_or_else(|_| format!("/run/user/{}", current_uid()));
            format!("unix:path={dir}/bus (the default: DBUS_SESSION_BUS_ADDRESS is not set)")
        })
    };
    let (builder, what) = match (&bus.address, bus.system) {
        (Some(a), _) => (
            zbus::connection::Builder::address(a.as_str()),
            format!("the bus at {a} (--address)"),
        ),
        (None, true) => (
            zbus::connection::Builder::system(),
            format!(
                "the system bus at {}",
                std::env::var("DBUS_SYSTEM_BUS_ADDRESS")
                    .unwrap_or_else(|_| "unix:path=/run/dbus/system_bus_socket".into())
            ),
        ),
        (None, false) => (
            zbus::connection::Builder::session(),
            format!("the session bus at {}", session_address()),
        ),
    };
    let fail = |cause: String| {
        anyhow::anyhow!(
            "cannot connect to {what}: {cause}\nhint: volcapd serves org.volcap.Capture1 on the bus its config names ([dbus] bus); \
             choose that one with --system (production) or --address ADDRESS, or set DBUS_SESSION_BUS_ADDRESS"
        )
    };
    builder.build().await.map_err(|e| fail(root_cause(&e)))
}

/// The innermost cause of `e` (zbus wraps I/O errors and repeats their text).
fn root_cause(e: &(dyn std::error::Error + 'static)) -> String {
    let mut cur = e;
    while let Some(next) = cur.source() {
        cur = next;
    }
    cur.to_string()
}

/// This process's user id, from /proc (no libc call needed).
fn current_uid() -> String {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("Uid:"))
                .and_then(|l| l.split_whitespace().nth(1).map(String::from))
        })
        .unwrap_or_else(|| "UID".into())
}

/// A D-Bus error as the daemon worded it.
fn said(e: zbus::Error) -> anyhow::Error {
    match e {
        zbus::Error::MethodError(name, Some(msg), _) => anyhow::anyhow!("{msg} ({name})"),
        zbus::Error::FDO(f) => anyhow::anyhow!("{f}"),
        other => anyhow::anyhow!("{other}"),
    }
}

pub fn run(cmd: CtlCmd) -> Result<()> {
    let rt = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(1)
        .enable_all()
        .build()?;
    // A daemon that does not answer is an error, not a hang.
    rt.block_on(async {
        tokio::time::timeout(std::time::Duration::from_secs(15), run_async(cmd))
            .await
            .map_err(|_| anyhow::anyhow!("no answer from volcapd within 15 s"))?
    })
}

async fn run_async(cmd: CtlCmd) -> Result<()> {
    let bus = match &cmd {
        CtlCmd::Status { bus, .. }
        | CtlCmd::SetView { bus, .. }
        | CtlCmd::SetResolution { bus, .. }
        | CtlCmd::Pause { bus }
        | CtlCmd::Resume { bus }
        | CtlCmd::Reload { bus }
        | CtlCmd::Snapshot { bus, .. } => bus.clone(),
    };
    let conn = connect(&bus).await?;
    let proxy = Capture1Proxy::new(&conn)
        .await
        .context("no volcapd on this bus (org.volcap.Capture1)")?;
    match cmd {
        CtlCmd::Status { json, .. } => {
            let props = zbus::fdo::PropertiesProxy::builder(&conn)
                .destination("org.volcap.Capture1")
                .path("/org/volcap/Capture1")
                .build()
                .await?;
            let all = props
                .get_all("org.volcap.Capture1".try_into()?)
                .await
                .map_err(|e| anyhow::anyhow!("is volcapd running? {e}"))?;
            let mut rows: Vec<(String, serde_json::Value)> = all
                .into_iter()
                .map(|(k, v)| {
                    // zvariant serializes a variant as {signature, value}.
                    let mut j = serde_json::to_value(&v).unwrap_or(serde_json::Value::Null);
                    if let Some(inner) = j.get_mut("value") {
                        j = inner.take();
                    }
                    (k, j)
                })
                .collect();
            rows.sort_by(|a, b| a.0.cmp(&b.0));
            if json {
                let m: serde_json::Map<String, serde_json::Value> = rows.into_iter().collect();
                println!("{}", serde_json::Value::Object(m));
            } else {
                for (k, v) in rows {
                    let shown = match v {
                        serde_json::Value::String(s) => s,
                        other => other.to_string(),
                    };
                    println!("{k:<16} {shown}");
                }
            }
        }
        CtlCmd::SetView {
            yaw,
            pitch,
            distance,
            ..
        } => proxy.set_view(yaw, pitch, distance).await.map_err(said)?,
        CtlCmd::SetResolution { level, .. } => proxy.set_resolution(level).await.map_err(said)?,
        CtlCmd::Pause { .. } => proxy.pause().await.map_err(said)?,
        CtlCmd::Resume { .. } => proxy.resume().await.map_err(said)?,
        CtlCmd::Reload { .. } => println!("{}", proxy.reload().await.map_err(said)?),
        CtlCmd::Snapshot { out, .. } => {
            let png = proxy.snapshot().await.map_err(said)?;
            if !png.starts_with(b"\x89PNG") {
                bail!("the daemon sent {} bytes that are not a PNG", png.len());
            }
            std::fs::write(&out, &png).with_context(|| format!("writing {}", out.display()))?;
            println!("{} ({} bytes)", out.display(), png.len());
        }
    }
    Ok(())
}
