//! A bounded hand-off between two threads that never blocks the producer: when full, the oldest item gives
//! way (a live sensor wants the newest frame, not a backlog) and the loss is counted.

use std::collections::VecDeque;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Condvar, Mutex};
use std::time::Duration;

pub struct DropOldestQueue<T> {
    items: Mutex<VecDeque<T>>,
    ready: Condvar,
    capacity: usize,
    dropped: AtomicU64,
}

impl<T> DropOldestQueue<T> {
    pub fn new(capacity: usize) -> Self {
        Self {
            items: Mutex::new(VecDeque::new()),
            ready: Condvar::new(),
            capacity: capacity.max(1),
            dropped: AtomicU64::new(0),
        }
    }

    /// Adds an item; returns true when an older one had to be dropped for it.
    pub fn push(&self, item: T) -> bool {
        let mut items = self.items.lock().unwrap_or_else(|e| e.into_inner());
        let mut dropped = false;
        while items.len() >= self.capacity {
            items.pop_front();
            self.dropped.fetch_add(1, Ordering::Relaxed);
            dropped = true;
        }
        items.push_back(item);
        drop(items);
        self.ready.notify_one();
        dropped
    }

    /// The oldest item, waiting at most `timeout` for one.
    pub fn pop_timeout(&self, timeout: Duration) -> Option<T> {
        let items = self.items.lock().unwrap_or_else(|e| e.into_inner());
        let (mut items, _) = self
            .ready
            .wait_timeout_while(items, timeout, |items| items.is_empty())
            .unwrap_or_else(|e| e.into_inner());
        items.pop_front()
    }

    pub fn dropped(&self) -> u64 {
        self.dropped.load(Ordering::Relaxed)
    }

    pub fn len(&self) -> usize {
        self.items.lock().unwrap_or_else(|e| e.into_inner()).len()
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn overflow_drops_the_oldest_and_counts() {
        let queue = DropOldestQueue::new(2);
        assert!(!queue.push(1));
        assert!(!queue.push(2));
        assert!(queue.push(3));
        assert_eq!(queue.dropped(), 1);
        assert_eq!(queue.pop_timeout(Duration::ZERO), Some(2));
        assert_eq!(queue.pop_timeout(Duration::ZERO), Some(3));
        assert_eq!(queue.pop_timeout(Duration::from_millis(1)), None);
    }

    #[test]
    fn consumer_wakes_when_an_item_arrives() {
        let queue = std::sync::Arc::new(DropOldestQueue::new(4));
        let producer = queue.clone();
        let thread = std::thread::spawn(move || {
            std::thread::sleep(Duration::from_millis(20));
            producer.push(7u32);
        });
        assert_eq!(queue.pop_timeout(Duration::from_secs(5)), Some(7));
        thread.join().unwrap();
    }
}
