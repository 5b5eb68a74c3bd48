//! Work on a thread pool consumed in order, with a bounded window: [`for_each_in_order`], the
//! pipeline's LOD phase's pass over the cells (`crate::pipeline`).

use crate::error::BuildError;

/// How far [`for_each_in_order`] may run ahead of its consumer: at most `results` indices past
/// the one the consumer waits for, and, past that one, no new index while the results produced
/// and not yet consumed weigh more than `bytes`. Also what it held at most, as it returns.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub(crate) struct Window {
    pub results: usize,
    pub bytes: usize,
}

/// Runs `produce(i)` for `i` in `0..n` on `pool` (workers take indices in increasing order) and
/// hands the results to `consume` on the calling thread in index order, as soon as each is
/// ready. A worker does not start index `i` while it is `window.results` or more past the next
/// index to consume, nor, unless `i` is that index, while the produced results waiting for the
/// consumer weigh (`weigh`) more than `window.bytes`. So at most `window.results` + one per
/// worker results are held, and past `window.bytes` only one more per worker, however slow
/// `consume` is (without a window, a consumer slower than the pool let a whole bucket's cell
/// DAGs pile up: ~250 MB on the 10^8-triangle plant). The consumer always gets its next index:
/// the worker that took it does not wait. Workers call `side` (until it returns false: it ran
/// nothing) before taking an index and while the window holds them back: work that `consume`
/// queues for the pool. On the first error of `consume` the workers stop taking new indices
/// and the error is returned. Returns the most it held.
pub(crate) fn for_each_in_order<T, P, W, C>(
    pool: &rayon::ThreadPool,
    n: usize,
    window: Window,
    produce: P,
    side: &(dyn Fn() -> bool + Sync),
    weigh: W,
    consume: C,
) -> Result<Window, BuildError>
where
    T: Send,
    P: Fn(usize) -> T + Sync,
    W: Fn(&T) -> usize + Sync,
    C: FnMut(usize, T) -> Result<(), BuildError>,
{
    let shared = InOrder { n, window, ..InOrder::default() };
    let (tx, rx) = std::sync::mpsc::channel::<(usize, T, usize)>();
    std::thread::scope(|scope| {
        let (shared, produce, weigh) = (&shared, &produce, &weigh);
        scope.spawn(move || {
            pool.scope(|s| {
                for _ in 0..pool.current_num_threads() {
                    let tx = tx.clone();
                    s.spawn(move |_| shared.work(side, produce, weigh, &tx));
                }
            });
            drop(tx);
        });
        shared.consume_in_order(rx, consume)
    })
}

/// Results produced and consumed so far by [`for_each_in_order`], the weight of those not yet
/// consumed, and the most held.
#[derive(Default)]
struct Ahead {
    produced: usize,
    consumed: usize,
    bytes: usize,
    most: Window,
}

/// What [`for_each_in_order`]'s workers and consumer share: the next index to take, the stop
/// flag, the count of results ahead of the consumer and a condition to wait for the consumer.
#[derive(Default)]
struct InOrder {
    n: usize,
    window: Window,
    next: std::sync::atomic::AtomicUsize,
    stop: std::sync::atomic::AtomicBool,
    ahead: std::sync::Mutex<Ahead>,
    consumed: std::sync::Condvar,
}

impl InOrder {
    fn lock(&self) -> std::sync::MutexGuard<'_, Ahead> {
        self.ahead.lock().unwrap_or_else(|e| e.into_inner())
    }

    fn stopped(&self) -> bool {
        self.stop.load(std::sync::atomic::Ordering::Relaxed)
    }

    /// One worker: side jobs, then the next index once the window lets it, its result sent
    /// to the consumer; until the indices run out or the consumer stops.
    fn work<T, P, W>(&self, side: &(dyn Fn() -> bool + Sync), produce: &P, weigh: &W, tx: &Sender<T>)
    where
        P: Fn(usize) -> T,
        W: Fn(&T) -> usize,
    {
        loop {
            // Side jobs first: the consumer will need them before the next index.
            while !self.stopped() && side() {}
            if self.stopped() {
                return;
            }
            let i = self.next.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
            if i >= self.n {
                return;
            }
            self.wait_for_window(i, side);
            if self.stopped() {
                return;
            }
            let result = produce(i);
            let weight = weigh(&result);
            self.record_produced(weight);
            if tx.send((i, result, weight)).is_err() {
                return;
            }
        }
    }

    /// Holds a worker back until index `i` fits the window (or the consumer stops), doing side
    /// jobs meanwhile: the consumer starts them, and wakes the workers after every result it
    /// takes.
    fn wait_for_window(&self, i: usize, side: &(dyn Fn() -> bool + Sync)) {
        let window = self.window;
        let fits =
            |st: &Ahead| i < st.consumed + window.results && (i == st.consumed || st.bytes <= window.bytes);
        let mut st = self.lock();
        while !self.stopped() && !fits(&st) {
            drop(st);
            let ran = side();
            st = self.lock();
            if !ran && !fits(&st) {
                st = self.consumed.wait(st).unwrap_or_else(|e| e.into_inner());
            }
        }
    }

    /// Counts a result of `weight` bytes produced, and the most held.
    fn record_produced(&self, weight: usize) {
        let mut st = self.lock();
        st.produced += 1;
        st.bytes += weight;
        st.most.results = st.most.results.max(st.produced - st.consumed);
        st.most.bytes = st.most.bytes.max(st.bytes);
    }

    /// The consumer: takes the results in index order as they arrive (those that come before
    /// their turn wait, with their weights), wakes the workers after each, and stops them at
    /// its first error.
    fn consume_in_order<T, C>(&self, rx: Receiver<T>, mut consume: C) -> Result<Window, BuildError>
    where
        C: FnMut(usize, T) -> Result<(), BuildError>,
    {
        let mut waiting: std::collections::BTreeMap<usize, (T, usize)> = std::collections::BTreeMap::new();
        let mut expected = 0usize;
        for (i, item, weight) in rx.iter() {
            waiting.insert(i, (item, weight));
            while let Some((item, weight)) = waiting.remove(&expected) {
                let result = consume(expected, item);
                if result.is_err() {
                    self.stop.store(true, std::sync::atomic::Ordering::Relaxed);
                }
                expected += 1;
                {
                    let mut st = self.lock();
                    st.consumed = expected;
                    st.bytes -= weight;
                }
                self.consumed.notify_all();
                result?;
            }
        }
        Ok(self.lock().most)
    }
}

/// The channel of [`for_each_in_order`]'s results: index, result and weight.
type Sender<T> = std::sync::mpsc::Sender<(usize, T, usize)>;
type Receiver<T> = std::sync::mpsc::Receiver<(usize, T, usize)>;

#[cfg(test)]
mod tests {
    use super::*;

    fn pool(n: usize) -> rayon::ThreadPool {
        rayon::ThreadPoolBuilder::new().num_threads(n).build().unwrap()
    }

    #[test]
    fn for_each_in_order_consumes_every_result_in_order() {
        for threads in [1, 2, 4] {
            let mut got = Vec::new();
            // Uneven work so that results arrive out of order.
            let produce = |i: usize| {
                std::thread::sleep(std::time::Duration::from_micros(((i * 7919) % 13) as u64 * 50));
                i * i
            };
            let window = Window { results: 16, bytes: usize::MAX };
            for_each_in_order(
                &pool(threads),
                100,
                window,
                produce,
                &|| false,
                |_| 0,
                |i, v| {
                    got.push((i, v));
                    Ok(())
                },
            )
            .unwrap();
            assert_eq!(got, (0..100).map(|i| (i, i * i)).collect::<Vec<_>>(), "{threads} threads");
        }
    }

    #[test]
    fn for_each_in_order_holds_a_bounded_number_of_results_for_a_slow_consumer() {
        use std::sync::atomic::{AtomicUsize, Ordering};
        let produced = AtomicUsize::new(0);
        let mut most_ahead = 0;
        let window = Window { results: 16, bytes: usize::MAX };
        let held = for_each_in_order(
            &pool(4),
            200,
            window,
            |i| {
                produced.fetch_add(1, Ordering::SeqCst);
                i
            },
            &|| false,
            |_| 0,
            |i, _| {
                std::thread::sleep(std::time::Duration::from_micros(200));
                most_ahead = most_ahead.max(produced.load(Ordering::SeqCst) - i);
                Ok(())
            },
        )
        .unwrap();
        assert!(most_ahead <= window.results + 4, "{most_ahead} results held");
        assert!(held.results <= window.results + 4 && held.results >= 2, "{held:?}");
    }

    #[test]
    fn for_each_in_order_holds_a_bounded_weight_for_a_slow_consumer() {
        // Results of 1,000 bytes, at most 2,500 held: the count window (16) never binds, the
        // weight does, and every result still arrives in order.
        let window = Window { results: 16, bytes: 2_500 };
        for threads in [1, 2, 4] {
            let mut got = Vec::new();
            let held = for_each_in_order(
                &pool(threads),
                200,
                window,
                |i| vec![i as u8; 1_000],
                &|| false,
                |v| v.len(),
                |i, v| {
                    std::thread::sleep(std::time::Duration::from_micros(100));
                    got.push((i, v[0]));
                    Ok(())
                },
            )
            .unwrap();
            assert_eq!(got, (0..200).map(|i| (i, i as u8)).collect::<Vec<_>>(), "{threads} threads");
            // Past the weight, one more result per worker (and the consumer's next one).
            assert!(held.bytes <= 2_500 + 1_000 * (threads + 1), "{threads} threads: {held:?}");
        }
    }

    #[test]
    fn for_each_in_order_makes_progress_when_one_result_outweighs_the_window() {
        let window = Window { results: 4, bytes: 10 };
        let mut got = 0;
        for_each_in_order(
            &pool(3),
            50,
            window,
            |i| vec![0u8; 100 + i],
            &|| false,
            |v| v.len(),
            |_, _| {
                got += 1;
                Ok(())
            },
        )
        .unwrap();
        assert_eq!(got, 50);
    }

    #[test]
    fn for_each_in_order_runs_side_jobs_on_the_workers() {
        use std::sync::atomic::{AtomicUsize, Ordering};
        // The consumer queues a side job with every result; workers take them between indices.
        let queued = AtomicUsize::new(0);
        let ran = AtomicUsize::new(0);
        let side = || {
            let take = queued.fetch_update(Ordering::SeqCst, Ordering::SeqCst, |q| q.checked_sub(1)).is_ok();
            if take {
                ran.fetch_add(1, Ordering::SeqCst);
            }
            take
        };
        let mut got = 0;
        for_each_in_order(
            &pool(2),
            300,
            Window { results: 4, bytes: usize::MAX },
            |i| {
                std::thread::sleep(std::time::Duration::from_micros(50));
                i
            },
            &side,
            |_| 0,
            |i, v| {
                assert_eq!(i, v);
                got += 1;
                queued.fetch_add(1, Ordering::SeqCst);
                Ok(())
            },
        )
        .unwrap();
        assert_eq!(got, 300);
        assert!(ran.load(Ordering::SeqCst) > 0, "no side job ran on a worker");
    }

    #[test]
    fn for_each_in_order_handles_nothing() {
        let window = Window { results: 16, bytes: usize::MAX };
        for_each_in_order(&pool(2), 0, window, |i| i, &|| false, |_| 0, |_, _| panic!("nothing to consume"))
            .unwrap();
    }

    #[test]
    fn for_each_in_order_stops_at_the_first_error() {
        let produced = std::sync::atomic::AtomicUsize::new(0);
        let mut consumed = Vec::new();
        let r = for_each_in_order(
            &pool(2),
            100_000,
            Window { results: 16, bytes: usize::MAX },
            |i| {
                produced.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                std::thread::sleep(std::time::Duration::from_micros(20));
                i
            },
            &|| false,
            |_| 0,
            |i, _| {
                consumed.push(i);
                if i == 5 {
                    Err(BuildError::Param("stop".into()))
                } else {
                    Ok(())
                }
            },
        );
        assert!(matches!(r, Err(BuildError::Param(m)) if m == "stop"));
        assert_eq!(consumed, (0..=5).collect::<Vec<_>>());
        assert!(produced.load(std::sync::atomic::Ordering::Relaxed) < 100_000, "workers stopped early");
    }
}
