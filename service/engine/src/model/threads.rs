//! tract's thread pool for the networks' matrix products.

/// Run `f` with tract's matrix products (the networks' convolutions) spread over `threads`
/// threads: a pool per thread count, made once and kept. With 1, or when no pool can be
/// made, `f` runs on the calling thread alone. Results do not depend on it beyond float
/// summation order.
pub fn with_threads<R>(threads: usize, f: impl FnOnce() -> R) -> R {
    use tract_linalg::multithread::{Executor, multithread_tract_scope};
    static POOLS: std::sync::Mutex<Vec<(usize, Option<Executor>)>> =
        std::sync::Mutex::new(Vec::new());
    if threads <= 1 {
        return f();
    }
    let exec = {
        let mut pools = POOLS.lock().unwrap_or_else(|p| p.into_inner());
        match pools.iter().find(|(n, _)| *n == threads) {
            Some((_, e)) => e.clone(),
            None => {
                // tract panics when the pool cannot be built (no threads left): run alone.
                let e = std::panic::catch_unwind(|| {
                    Executor::multithread_with_name(threads, "volcap-tract")
                })
                .ok();
                pools.push((threads, e.clone()));
                e
            }
        }
    };
    match exec {
        Some(e) => multithread_tract_scope(e, f),
        None => f(),
    }
}
