//! Which runtime runs the networks: tract (pure Rust, built in, the default) or ONNX Runtime
//! (its shared library loaded at run time, `[compute] runtime`).
//!
//! ONNX Runtime runs our networks 2-5x faster on x86 (its convolution kernels, and int8
//! through VNNI where tract's QDQ graphs quantize and dequantize around f32 products:
//! `volcap bench nets --profile`). It is a shared library taken from the pinned
//! `onnxruntime` PyPI wheel (`tools/onnxruntime.sh`), never downloaded at build or run time:
//! without it the appliance runs on tract as before. The library is loaded once per
//! process (its path is then fixed).

use std::path::{Path, PathBuf};
use std::sync::Arc;

/// `[compute] runtime`: what the configuration asks for (`tract`, `onnxruntime`, `auto`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum RuntimeChoice {
    /// tract, always available.
    Tract,
    /// ONNX Runtime, an error when its library cannot be loaded.
    OnnxRuntime,
    /// ONNX Runtime when its library is found and loads, else tract (with the reason).
    #[default]
    Auto,
}

impl RuntimeChoice {
    pub fn parse(s: &str) -> Result<Self, String> {
        match s {
            "tract" => Ok(Self::Tract),
            "onnxruntime" => Ok(Self::OnnxRuntime),
            "auto" => Ok(Self::Auto),
            other => Err(format!(
                "runtime = {other:?}: need \"tract\", \"onnxruntime\" or \"auto\""
            )),
        }
    }

    pub fn as_str(&self) -> &'static str {
        match self {
            Self::Tract => "tract",
            Self::OnnxRuntime => "onnxruntime",
            Self::Auto => "auto",
        }
    }
}

/// The library's file name in the places searched ([`find_library`]).
pub const LIBRARY_NAME: &str = "libonnxruntime.so";

/// Where the library is looked for when no path is configured: `$VOLCAP_ONNXRUNTIME` (a
/// file), then `/usr/lib/volcap/onnxruntime/` (tools/install.sh), then the checkout's
/// `target/onnxruntime/` (what `tools/onnxruntime.sh` fetches): the `target/` the
/// executable was built in, or one in the current folder or above it.
pub fn find_library(configured: Option<&Path>) -> Option<PathBuf> {
    if let Some(p) = configured {
        return Some(p.to_path_buf());
    }
    if let Some(p) = std::env::var_os("VOLCAP_ONNXRUNTIME") {
        return Some(PathBuf::from(p));
    }
    let mut places = vec![PathBuf::from("/usr/lib/volcap/onnxruntime").join(LIBRARY_NAME)];
    // target/release/volcapd, target/release/deps/<test> -> target/onnxruntime/
    if let Ok(exe) = std::env::current_exe() {
        places.extend(
            exe.ancestors()
                .filter(|a| a.file_name().is_some_and(|n| n == "target"))
                .map(|t| t.join("onnxruntime").join(LIBRARY_NAME)),
        );
    }
    if let Ok(cwd) = std::env::current_dir() {
        places.extend(
            cwd.ancestors()
                .map(|a| a.join("target").join("onnxruntime").join(LIBRARY_NAME)),
        );
    }
    places.into_iter().find(|p| p.is_file())
}

/// The runtime the networks are loaded on.
#[derive(Clone, Default)]
pub enum Runtime {
    #[default]
    Tract,
    #[cfg(feature = "onnxruntime")]
    OnnxRuntime(Arc<ort_backend::OrtRuntime>),
    /// The GPU backend's kernels on one adapter (`[compute] backend = "wgpu"`).
    #[cfg(feature = "wgpu")]
    Wgpu(Arc<crate::gpu::Gpu>),
}

impl std::fmt::Debug for Runtime {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.label())
    }
}

/// What opening a runtime gave: the runtime and, when `auto` fell back to tract, why.
pub struct Opened {
    pub runtime: Runtime,
    pub fallback: Option<String>,
}

impl Runtime {
    /// The runtime for `choice`; `lib` is the configured library path (none: searched,
    /// [`find_library`]). `onnxruntime` fails with the reason when the library is missing
    /// or does not load; `auto` then falls back to tract and says why.
    pub fn open(choice: RuntimeChoice, lib: Option<&Path>) -> Result<Opened, String> {
        let tract = |fallback| Opened {
            runtime: Runtime::Tract,
            fallback,
        };
        match choice {
            RuntimeChoice::Tract => Ok(tract(None)),
            RuntimeChoice::OnnxRuntime => Self::onnxruntime(lib).map(|runtime| Opened {
                runtime,
                fallback: None,
            }),
            RuntimeChoice::Auto => Ok(match Self::onnxruntime(lib) {
                Ok(runtime) => Opened {
                    runtime,
                    fallback: None,
                },
                Err(why) => tract(Some(why)),
            }),
        }
    }

    #[cfg(feature = "onnxruntime")]
    fn onnxruntime(lib: Option<&Path>) -> Result<Runtime, String> {
        let path = find_library(lib).ok_or_else(|| {
            format!(
                "ONNX Runtime's library is not installed ({LIBRARY_NAME} not in /usr/lib/volcap/onnxruntime/ \
                 or target/onnxruntime/, $VOLCAP_ONNXRUNTIME unset): fetch it with tools/onnxruntime.sh"
            )
        })?;
        ort_backend::OrtRuntime::get(&path).map(Runtime::OnnxRuntime)
    }

    #[cfg(not(feature = "onnxruntime"))]
    fn onnxruntime(_lib: Option<&Path>) -> Result<Runtime, String> {
        Err("this build has no ONNX Runtime support (the engine's `onnxruntime` feature)".into())
    }

    /// "tract", "onnxruntime 1.32.0" or "wgpu llvmpipe (LLVM 15.0.6, 256 bits)".
    pub fn label(&self) -> String {
        match self {
            Runtime::Tract => "tract".into(),
            #[cfg(feature = "onnxruntime")]
            Runtime::OnnxRuntime(o) => format!("onnxruntime {}", o.version),
            #[cfg(feature = "wgpu")]
            Runtime::Wgpu(g) => format!("wgpu {}{}", g.adapter.name, {
                use crate::gpu::net::plan::ConvKernels as K;
                match g.conv_kernels() {
                    k if k == K::for_device_type(&g.adapter.device_type) => "",
                    K::Split => " (split convolutions)",
                    K::Rows => " (no split convolutions)",
                    K::Conv4 => " (conv4 only)",
                }
            }),
        }
    }

    /// The short name: "tract", "onnxruntime" or "wgpu".
    pub fn name(&self) -> &'static str {
        match self {
            Runtime::Tract => "tract",
            #[cfg(feature = "onnxruntime")]
            Runtime::OnnxRuntime(_) => "onnxruntime",
            #[cfg(feature = "wgpu")]
            Runtime::Wgpu(_) => "wgpu",
        }
    }

    /// The adapter the networks run on, when it is the GPU backend.
    #[cfg(feature = "wgpu")]
    pub fn gpu(&self) -> Option<&Arc<crate::gpu::Gpu>> {
        match self {
            Runtime::Wgpu(g) => Some(g),
            _ => None,
        }
    }
}

#[cfg(feature = "onnxruntime")]
pub(crate) mod ort_backend {
    use std::path::{Path, PathBuf};
    use std::sync::{Arc, Mutex, OnceLock};

    /// ONNX Runtime's library, loaded once per process, and its environment.
    pub struct OrtRuntime {
        pub env: ort::environment::Environment,
        pub path: PathBuf,
        pub version: String,
    }

    static LOADED: OnceLock<Result<Arc<OrtRuntime>, String>> = OnceLock::new();

    impl OrtRuntime {
        /// The runtime from `path`; the first call loads it and every later call gets the
        /// same one (another path than the loaded one is an error: one library per process).
        pub fn get(path: &Path) -> Result<Arc<OrtRuntime>, String> {
            let loaded = LOADED.get_or_init(|| Self::load(path));
            match loaded {
                Ok(rt) if rt.path != path => Err(format!(
                    "ONNX Runtime is already loaded from {} in this process; {} cannot be loaded beside it",
                    rt.path.display(),
                    path.display()
                )),
                other => other.clone(),
            }
        }

        fn load(path: &Path) -> Result<Arc<OrtRuntime>, String> {
            if !path.is_file() {
                return Err(format!(
                    "{}: no such file (ONNX Runtime's library)",
                    path.display()
                ));
            }
            let env = ort::init_from(path)
                .map_err(|e| format!("{}: cannot load ONNX Runtime: {e}", path.display()))?
                .with_name("volcap")
                .build()
                .map_err(|e| format!("{}: cannot start ONNX Runtime: {e}", path.display()))?;
            // The version from the installed file's name (libonnxruntime.so -> the
            // libonnxruntime.so.1.32.0 it links to; tools/onnxruntime.sh installs it so).
            let version = std::fs::canonicalize(path)
                .ok()
                .and_then(|p| p.file_name().map(|f| f.to_string_lossy().to_string()))
                .and_then(|f| f.strip_prefix("libonnxruntime.so.").map(str::to_string))
                .unwrap_or_else(|| "(version unknown)".into());
            Ok(Arc::new(OrtRuntime {
                env,
                path: path.to_path_buf(),
                version,
            }))
        }
    }

    /// One network's ONNX Runtime session (one run at a time: `Session::run` takes it
    /// mutably).
    pub struct OrtNet {
        session: Mutex<ort::session::Session>,
        inputs: Vec<String>,
    }

    impl OrtNet {
        /// A session on `path`, one intra-op thread (the pipeline's threads are its stages).
        pub fn load(rt: &OrtRuntime, path: &Path) -> Result<OrtNet, String> {
            use ort::session::builder::GraphOptimizationLevel;
            let session = ort::session::Session::builder(&rt.env)
                .map_err(|e| e.to_string())?
                .with_optimization_level(GraphOptimizationLevel::Level3)
                .map_err(|e| e.to_string())?
                .with_intra_threads(1)
                .map_err(|e| e.to_string())?
                .with_inter_threads(1)
                .map_err(|e| e.to_string())?
                .commit_from_file(path)
                .map_err(|e| format!("ONNX Runtime cannot load it: {e}"))?;
            let inputs = session
                .inputs()
                .iter()
                .map(|i| i.name().to_string())
                .collect();
            Ok(OrtNet {
                session: Mutex::new(session),
                inputs,
            })
        }

        /// Run on f32 inputs (shape, data) in the graph's input order; the first output.
        pub fn run(&self, inputs: &[(&[usize], &[f32])]) -> Result<Vec<f32>, String> {
            if inputs.len() != self.inputs.len() {
                return Err(format!(
                    "{} inputs given, the graph takes {}",
                    inputs.len(),
                    self.inputs.len()
                ));
            }
            let mut values = Vec::with_capacity(inputs.len());
            for (name, (shape, data)) in self.inputs.iter().zip(inputs) {
                let t = ort::value::TensorRef::from_array_view((shape.to_vec(), *data))
                    .map_err(|e| e.to_string())?;
                values.push((name.as_str(), ort::session::SessionInputValue::from(t)));
            }
            let mut session = self.session.lock().unwrap_or_else(|p| p.into_inner());
            let out = session.run(values).map_err(|e| e.to_string())?;
            let (_, v) = out[0]
                .try_extract_tensor::<f32>()
                .map_err(|e| e.to_string())?;
            Ok(v.to_vec())
        }
    }
}
