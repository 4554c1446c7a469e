//! The latest-wins slot that joins pipeline stages, and the rolling per-stage timings.

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Condvar, Mutex};
use std::time::{Duration, Instant};

/// A one-item slot: `put` replaces what is there (and reports the overwrite), `take` waits.
/// `put_newer` keeps the items in order when several producers fill it (the render stage's
/// workers): an item older than the newest one put that way is refused.
pub struct Slot<T> {
    item: Mutex<Held<T>>,
    ready: Condvar,
    emptied: Condvar,
}

struct Held<T> {
    item: Option<T>,
    /// The newest `put_newer` key so far, kept after its item is taken.
    newest: Option<Instant>,
}

/// What `Slot::put_newer` did with an item.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Put {
    /// Put into an empty slot.
    Fresh,
    /// Put over an item nobody took (a drop of the producer's, as `put`'s `true`).
    Replaced,
    /// Refused: an item of a later key was put already (taken or not).
    Stale,
}

impl<T> Default for Slot<T> {
    fn default() -> Self {
        Self {
            item: Mutex::new(Held {
                item: None,
                newest: None,
            }),
            ready: Condvar::new(),
            emptied: Condvar::new(),
        }
    }
}

impl<T> Slot<T> {
    /// Put `v`; returns true when an unconsumed item was overwritten (a drop).
    pub fn put(&self, v: T) -> bool {
        let mut g = self.item.lock().unwrap_or_else(|p| p.into_inner());
        let dropped = g.item.replace(v).is_some();
        self.ready.notify_one();
        dropped
    }

    /// Put `v`, keyed by `at` (when its frame was captured), unless an item with a later key
    /// went in through here first: producers that finish out of order never put an older
    /// frame after a newer one, taken or not. Equal keys go in (the same frame again).
    pub fn put_newer(&self, v: T, at: Instant) -> Put {
        let mut g = self.item.lock().unwrap_or_else(|p| p.into_inner());
        if g.newest.is_some_and(|n| n > at) {
            return Put::Stale;
        }
        g.newest = Some(at);
        let dropped = g.item.replace(v).is_some();
        self.ready.notify_one();
        if dropped { Put::Replaced } else { Put::Fresh }
    }

    /// Take the latest item, waiting up to `timeout`.
    pub fn take(&self, timeout: Duration) -> Option<T> {
        let g = self.item.lock().unwrap_or_else(|p| p.into_inner());
        let (mut g, _) = self
            .ready
            .wait_timeout_while(g, timeout, |v| v.item.is_none())
            .unwrap_or_else(|p| p.into_inner());
        let v = g.item.take();
        if v.is_some() {
            self.emptied.notify_all();
        }
        v
    }

    /// Wait up to `timeout` until the slot is empty (its item taken); true when it is. A
    /// producer that waits here before computing the next item works only as fast as its
    /// consumer takes (no work thrown away on a bottleneck further down).
    pub fn wait_empty(&self, timeout: Duration) -> bool {
        let g = self.item.lock().unwrap_or_else(|p| p.into_inner());
        let (g, _) = self
            .emptied
            .wait_timeout_while(g, timeout, |v| v.item.is_some())
            .unwrap_or_else(|p| p.into_inner());
        g.item.is_none()
    }
}

/// Rolling per-stage timings: the last 256 (when, ms) samples.
#[derive(Default)]
pub struct StageStats {
    samples: Mutex<std::collections::VecDeque<(Instant, f64)>>,
    pub frames: AtomicU64,
    /// Items this stage put into its latest-wins slot that were replaced by a newer one
    /// before the next stage took them, or (a stage of several workers) that `put_newer`
    /// refused because a newer one went in first: work nobody needed (latest frame wins,
    /// nothing queues), not frames lost.
    pub superseded: AtomicU64,
    /// Frames this stage failed on (an error, not "no person in view"): frames lost.
    pub lost: AtomicU64,
}

impl StageStats {
    pub fn record(&self, ms: f64) {
        let mut s = self.samples.lock().unwrap_or_else(|p| p.into_inner());
        if s.len() >= 256 {
            s.pop_front();
        }
        s.push_back((Instant::now(), ms));
        self.frames.fetch_add(1, Ordering::Relaxed);
    }

    /// Time since the last sample (`None` before the first).
    pub fn since_last(&self) -> Option<Duration> {
        let s = self.samples.lock().unwrap_or_else(|p| p.into_inner());
        s.back().map(|(t, _)| t.elapsed())
    }

    /// Frames per second over the last 5 s (0 when none).
    pub fn recent_fps(&self) -> f64 {
        let s = self.samples.lock().unwrap_or_else(|p| p.into_inner());
        let window = Duration::from_secs(5);
        // Samples are in time order: the recent ones are a suffix.
        let recent = s.iter().skip_while(|(t, _)| t.elapsed() > window);
        let (n, first) = recent.fold((0usize, None), |(n, f), (t, _)| (n + 1, f.or(Some(*t))));
        match first {
            Some(first) if n > 1 => (n - 1) as f64 / first.elapsed().as_secs_f64().max(1e-3),
            _ => 0.0,
        }
    }

    /// (p50, p99, samples) in ms of the samples recorded since `since` (of the last 256).
    pub fn window(&self, since: Instant) -> (f64, f64, usize) {
        let mut v: Vec<f64> = self
            .samples
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .iter()
            .filter(|(t, _)| *t >= since)
            .map(|(_, ms)| *ms)
            .collect();
        if v.is_empty() {
            return (0.0, 0.0, 0);
        }
        v.sort_by(f64::total_cmp);
        let q = |p: f64| v[((v.len() - 1) as f64 * p).round() as usize];
        (q(0.5), q(0.99), v.len())
    }

    /// The mean in ms of the samples taken since `since` (0 when none): the parts of a stage
    /// add up in means, not in medians.
    pub fn mean(&self, since: Instant) -> f64 {
        let s = self.samples.lock().unwrap_or_else(|p| p.into_inner());
        let (sum, n) = s
            .iter()
            .filter(|(t, _)| *t >= since)
            .fold((0.0, 0usize), |(a, n), (_, ms)| (a + ms, n + 1));
        if n == 0 { 0.0 } else { sum / n as f64 }
    }

    /// (p50, p99) in ms over the last 256 frames.
    pub fn percentiles(&self) -> (f64, f64) {
        let (p50, p99, _) = self.window(self.samples_start());
        (p50, p99)
    }

    /// When the oldest kept sample was taken (now, when there is none).
    fn samples_start(&self) -> Instant {
        self.samples
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .front()
            .map_or_else(Instant::now, |(t, _)| *t)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::Arc;

    #[test]
    fn a_slot_tells_its_producer_when_it_was_taken() {
        let slot: Arc<Slot<u32>> = Arc::default();
        assert!(slot.wait_empty(Duration::from_millis(1)), "empty at first");
        assert!(!slot.put(1));
        assert!(!slot.wait_empty(Duration::from_millis(20)), "not taken yet");
        let s2 = slot.clone();
        let consumer = std::thread::spawn(move || {
            std::thread::sleep(Duration::from_millis(50));
            s2.take(Duration::from_secs(1))
        });
        let t = Instant::now();
        assert!(slot.wait_empty(Duration::from_secs(5)));
        assert!(t.elapsed() < Duration::from_secs(2));
        assert_eq!(consumer.join().unwrap(), Some(1));
        // Latest wins: a put over an unconsumed item reports the drop.
        slot.put(2);
        assert!(slot.put(3));
        assert_eq!(slot.take(Duration::from_millis(1)), Some(3));
    }

    #[test]
    fn put_newer_never_puts_an_older_frame_after_a_newer_one() {
        let slot: Slot<u32> = Slot::default();
        let t0 = Instant::now();
        let at = |ms: u64| t0 + Duration::from_millis(ms);
        assert_eq!(slot.put_newer(10, at(10)), Put::Fresh);
        // Finished after frame 10 but captured before it: refused, 10 stays.
        assert_eq!(slot.put_newer(9, at(9)), Put::Stale);
        assert_eq!(slot.take(Duration::from_millis(1)), Some(10));
        // Refused after the newer one was taken too: the consumer never goes back in time.
        assert_eq!(slot.put_newer(8, at(8)), Put::Stale);
        assert_eq!(slot.take(Duration::from_millis(1)), None);
        assert_eq!(slot.put_newer(11, at(11)), Put::Fresh);
        assert_eq!(slot.put_newer(12, at(12)), Put::Replaced);
        // The same capture time goes in (a frame rendered again).
        assert_eq!(slot.put_newer(13, at(12)), Put::Replaced);
        // A plain put (a placeholder) goes in and does not move the key.
        assert!(slot.put(99));
        assert_eq!(slot.put_newer(7, at(7)), Put::Stale);
        assert_eq!(slot.take(Duration::from_millis(1)), Some(99));
    }

    #[test]
    fn producers_racing_through_put_newer_deliver_in_capture_order() {
        // Four producers finish frames in shuffled order; a consumer takes as it can. What it
        // sees only ever moves forward in capture time, and the newest frame always arrives.
        let slot: Arc<Slot<u64>> = Arc::default();
        let t0 = Instant::now();
        let done = Arc::new(std::sync::atomic::AtomicBool::new(false));
        let consumer = {
            let (slot, done) = (slot.clone(), done.clone());
            std::thread::spawn(move || {
                let mut seen = Vec::new();
                while !done.load(std::sync::atomic::Ordering::SeqCst) {
                    if let Some(v) = slot.take(Duration::from_millis(1)) {
                        seen.push(v);
                    }
                }
                seen.extend(slot.take(Duration::from_millis(1)));
                seen
            })
        };
        let producers: Vec<_> = (0..4u64)
            .map(|w| {
                let slot = slot.clone();
                std::thread::spawn(move || {
                    for i in 0..500u64 {
                        // Each producer's frames in order, the producers' interleaving not.
                        let frame = i * 4 + w;
                        slot.put_newer(frame, t0 + Duration::from_micros(frame));
                        if (i + w) % 7 == 0 {
                            std::thread::yield_now();
                        }
                    }
                })
            })
            .collect();
        for p in producers {
            p.join().unwrap();
        }
        done.store(true, std::sync::atomic::Ordering::SeqCst);
        let seen = consumer.join().unwrap();
        assert!(!seen.is_empty());
        assert!(seen.windows(2).all(|w| w[0] < w[1]), "{seen:?}");
        assert_eq!(*seen.last().unwrap(), 1999, "the newest frame arrives");
    }
}
