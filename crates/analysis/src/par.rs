//! Work spread over threads: two on the diagnosis's and the store's
//! paths, as many as asked elsewhere.

/// `f` on every item (with its index), on at most two threads (fewer
/// when the machine has fewer cores): [`on_threads`]. Two: the work this
/// is for (logs read, diagnoses, candidates scored) runs on 2-core
/// benches and laptops, and a diagnosis already fits its thermal layer on
/// a thread of its own beside its rate layer.
pub fn two_at_a_time<T: Sync, R: Send>(items: &[T], f: impl Fn(usize, &T) -> R + Sync) -> Vec<R> {
    let cores = std::thread::available_parallelism().map_or(1, usize::from);
    on_threads(cores.clamp(1, 2), items, f)
}

/// `f` on every item (with its index), on `workers` threads (at least
/// one, at most one per item), each taking the next item when it is
/// done, the results in the items' order. A worker's panic is raised
/// again when the scope ends.
pub fn on_threads<T: Sync, R: Send>(
    workers: usize,
    items: &[T],
    f: impl Fn(usize, &T) -> R + Sync,
) -> Vec<R> {
    let next = std::sync::atomic::AtomicUsize::new(0);
    let done = std::sync::Mutex::new(Vec::new());
    std::thread::scope(|s| {
        for _ in 0..workers.max(1).min(items.len()) {
            s.spawn(|| {
                loop {
                    let k = next.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                    let Some(item) = items.get(k) else { break };
                    let r = f(k, item);
                    done.lock()
                        .unwrap_or_else(std::sync::PoisonError::into_inner)
                        .push((k, r));
                }
            });
        }
    });
    let mut done = done
        .into_inner()
        .unwrap_or_else(std::sync::PoisonError::into_inner);
    done.sort_by_key(|(k, _)| *k);
    done.into_iter().map(|(_, r)| r).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_item_is_done_once_and_the_results_keep_the_items_order() {
        let items: Vec<u64> = (0..37).collect();
        let out = two_at_a_time(&items, |k, &x| {
            // Uneven work, so the two workers finish out of order.
            std::thread::sleep(std::time::Duration::from_micros((x % 5) * 200));
            (k, x * x)
        });
        assert_eq!(
            out,
            items
                .iter()
                .map(|&x| (x as usize, x * x))
                .collect::<Vec<_>>()
        );
        assert!(two_at_a_time(&[] as &[u8], |_, &x| x).is_empty());
        // More workers than items, and none asked: every item once, in order.
        assert_eq!(on_threads(8, &[1u8, 2, 3], |_, &x| x), [1, 2, 3]);
        assert_eq!(on_threads(0, &[1u8, 2], |_, &x| x), [1, 2]);
    }
}
