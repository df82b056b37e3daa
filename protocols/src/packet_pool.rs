//! Reusable datagram buffers for encoders that emit several packets per frame.

/// Room a fresh buffer starts with: a split VMC bundle, a VRChat message or an event fits.
const INITIAL_CAPACITY: usize = 1536;

/// Buffers for one frame's datagrams, reused frame after frame.
///
/// Never truncated: a frame that needs fewer packets than the last one keeps the spare buffers
/// (and their capacity) for the next, and only the first `used` are this frame's. So once the
/// frames have been seen at their largest, encoding into the pool allocates nothing.
#[derive(Clone, Debug, Default)]
pub struct PacketPool {
    buffers: Vec<Vec<u8>>,
    used: usize,
}

impl PacketPool {
    /// An empty pool.
    pub fn new() -> Self {
        Self::default()
    }

    /// Forgets this frame's packets, keeping every buffer.
    pub fn clear(&mut self) {
        self.used = 0;
    }

    /// A new empty packet at the end of this frame's, reusing a spare buffer when there is one.
    pub fn next_packet(&mut self) -> &mut Vec<u8> {
        if self.used == self.buffers.len() {
            self.buffers.push(Vec::with_capacity(INITIAL_CAPACITY));
        }
        let buf = &mut self.buffers[self.used];
        buf.clear();
        self.used += 1;
        buf
    }

    /// The last packet of this frame, if any, to append to.
    pub fn last_packet(&mut self) -> Option<&mut Vec<u8>> {
        self.used.checked_sub(1).map(|i| &mut self.buffers[i])
    }

    /// This frame's packets, in order.
    pub fn packets(&self) -> &[Vec<u8>] {
        &self.buffers[..self.used]
    }

    /// This frame's packets as plain vectors, dropping the spare buffers.
    pub fn into_packets(mut self) -> Vec<Vec<u8>> {
        self.buffers.truncate(self.used);
        self.buffers
    }
}

impl From<Vec<Vec<u8>>> for PacketPool {
    /// A pool reusing `buffers` (their contents are discarded).
    fn from(buffers: Vec<Vec<u8>>) -> Self {
        Self { buffers, used: 0 }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keeps_spare_buffers_and_their_capacity() {
        let mut pool = PacketPool::new();
        for i in 0..3u8 {
            pool.next_packet().extend_from_slice(&[i; 2000]);
        }
        assert_eq!(pool.packets().len(), 3);
        let cap = pool.packets()[2].capacity();
        pool.clear();
        assert!(pool.last_packet().is_none());
        pool.next_packet().push(9);
        assert_eq!(pool.packets(), &[vec![9]]);
        pool.clear();
        for _ in 0..3 {
            pool.next_packet();
        }
        assert_eq!(pool.packets()[2].capacity(), cap);
        assert!(pool.packets()[2].is_empty());
        pool.clear();
        pool.next_packet().push(1);
        assert_eq!(pool.into_packets(), vec![vec![1]]);
        let mut reused = PacketPool::from(vec![vec![1, 2, 3]; 4]);
        reused.next_packet().push(7);
        assert_eq!(reused.into_packets(), vec![vec![7]]);
    }
}
