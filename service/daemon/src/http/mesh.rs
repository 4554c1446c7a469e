//! `/mesh.glb`: the current frame as a coloured glTF mesh, bounded and cached.

use super::App;
use axum::body::Bytes;
use axum::extract::State;
use axum::http::{StatusCode, header};
use axum::response::{IntoResponse, Response};
use std::sync::Arc;

/// The last mesh: its field (a `Weak` keeps the allocation, so a new frame's field can never
/// share its address), resolution, coarse level, and the bytes.
pub type MeshCache = (
    std::sync::Weak<volcap_sim::oracle::SceneField>,
    usize,
    u32,
    Bytes,
);

/// Mesh computations at once. Each holds one grid at the live resolution (4 bytes a point:
/// 68 MB at 257^3, 540 MB at 513^3) and its mesh; the localization is the paper's
/// hierarchical method.
pub const MESH_CONCURRENCY: usize = 1;

/// The current frame as a coloured mesh: hierarchical localization at the render
/// resolution, marching cubes, glTF binary. Slower than a frame (hundreds of ms): it runs off
/// the async runtime, [`MESH_CONCURRENCY`] at a time (others get 503 with Retry-After), and
/// its bytes are cached for the frame, so a repeated request for the same frame costs
/// nothing. A client that leaves does not cancel the computation, but it cannot start
/// another one: the work in flight stays bounded and fills the cache.
pub(super) async fn mesh_glb(State(app): State<Arc<App>>) -> Response {
    let Some(field) = app.shared.latest_field() else {
        return (StatusCode::SERVICE_UNAVAILABLE, "no frame yet\n").into_response();
    };
    let live = app.shared.live();
    let (res, coarse) = (live.resolution, live.coarse_level);
    let key = Arc::downgrade(&field);
    let glb_response =
        |b: Bytes| ([(header::CONTENT_TYPE, "model/gltf-binary")], b).into_response();
    let cached = |app: &App| {
        app.mesh_cache
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .as_ref()
            .filter(|(k, r, c, _)| k.as_ptr() == Arc::as_ptr(&field) && (*r, *c) == (res, coarse))
            .map(|(_, _, _, b)| b.clone())
    };
    if let Some(b) = cached(&app) {
        return glb_response(b);
    }
    let Ok(permit) = app.mesh_gate.try_acquire() else {
        return (
            StatusCode::SERVICE_UNAVAILABLE,
            [(header::RETRY_AFTER, "1")],
            "a mesh is being computed; retry in a second\n",
        )
            .into_response();
    };
    // The frame may have been meshed while we waited for the gate.
    if let Some(b) = cached(&app) {
        return glb_response(b);
    }
    let app2 = app.clone();
    let glb = tokio::task::spawn_blocking(move || -> Result<Bytes, String> {
        let field = field;
        let spec =
            volcap_engine::grid::GridSpec::from_resolution(res).map_err(|e| e.to_string())?;
        let mut grid = volcap_engine::grid::Grid::new(spec);
        volcap_engine::localize::Localizer::new()
            .run(
                volcap_engine::localize::Method::Hierarchical,
                field.as_ref(),
                spec,
                coarse,
                &mut grid,
            )
            .map_err(|e| e.to_string())?;
        let mut mesh = volcap_engine::mesh::marching_cubes(&grid);
        drop(grid);
        mesh.paint(field.as_ref()).map_err(|e| e.to_string())?;
        let bytes = Bytes::from(mesh.to_glb());
        *app2.mesh_cache.lock().unwrap_or_else(|p| p.into_inner()) =
            Some((key, res, coarse, bytes.clone()));
        Ok(bytes)
    })
    .await;
    drop(permit);
    match glb {
        Ok(Ok(b)) => glb_response(b),
        Ok(Err(e)) => (
            StatusCode::INTERNAL_SERVER_ERROR,
            format!("mesh failed: {e}\n"),
        )
            .into_response(),
        Err(_) => (StatusCode::INTERNAL_SERVER_ERROR, "mesh task failed\n").into_response(),
    }
}

/// HEAD of the mesh: whether one can be had, computing nothing.
pub(super) async fn mesh_head(State(app): State<Arc<App>>) -> Response {
    if app.shared.latest_field().is_some() {
        ([(header::CONTENT_TYPE, "model/gltf-binary")], "").into_response()
    } else {
        StatusCode::SERVICE_UNAVAILABLE.into_response()
    }
}
