//! Work done off the frame: a job on its own thread, keyed by what it was started for, so a
//! newer request replaces an older one and a stale result is never installed.

use std::thread::JoinHandle;

/// At most one background job producing a `T` for the key `K`.
pub struct Background<K, T> {
    job: Option<(K, JoinHandle<T>)>,
}

impl<K, T> Default for Background<K, T> {
    fn default() -> Self {
        Self { job: None }
    }
}

impl<K: PartialEq, T: Send + 'static> Background<K, T> {
    /// Starts `work` for `key` on a new thread. A job already running is abandoned: it runs to
    /// its end, but its result is dropped.
    pub fn start(&mut self, key: K, name: &str, work: impl FnOnce() -> T + Send + 'static) {
        let handle = std::thread::Builder::new()
            .name(name.into())
            .spawn(work)
            .expect("the system can start a thread");
        self.job = Some((key, handle));
    }

    /// The key of the job running, if any.
    pub fn key(&self) -> Option<&K> {
        self.job.as_ref().map(|(k, _)| k)
    }

    /// True while a job is running.
    pub fn is_running(&self) -> bool {
        self.job.is_some()
    }

    /// The result of the job if it has finished (then the job is gone). A job that panicked
    /// gives `Err` with the panic message.
    pub fn poll(&mut self) -> Option<(K, Result<T, String>)> {
        if !self.job.as_ref()?.1.is_finished() {
            return None;
        }
        let (key, handle) = self.job.take()?;
        let result = handle.join().map_err(|e| {
            e.downcast_ref::<String>()
                .cloned()
                .or_else(|| e.downcast_ref::<&str>().map(|s| s.to_string()))
                .unwrap_or_else(|| "the job panicked".into())
        });
        Some((key, result))
    }
}
