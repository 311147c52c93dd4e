//! Counting-sort bucket tables in compressed rows: the items of bucket `b` are
//! `items[ptr[b]..ptr[b + 1]]`, in increasing item order. Built in two passes over the items
//! (count, prefix sum, fill), `O(items + buckets)`.

/// A bucket table: `ptr` (one more entry than buckets, from 0 to `items.len()`) and `items`.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct Buckets {
    pub ptr: Vec<u32>,
    pub items: Vec<u32>,
}

impl Buckets {
    /// Put each of `n_items` items into the buckets `buckets_of(item)` names (each `< n_buckets`;
    /// called twice per item, and must name the same buckets both times).
    pub fn build<I: IntoIterator<Item = usize>>(n_buckets: usize, n_items: usize, buckets_of: impl Fn(usize) -> I) -> Buckets {
        let ptr = offsets(n_buckets, (0..n_items).flat_map(&buckets_of));
        let mut fill = ptr.clone();
        let mut items = vec![0u32; *ptr.last().unwrap() as usize];
        for t in 0..n_items {
            for b in buckets_of(t) {
                items[fill[b] as usize] = t as u32;
                fill[b] += 1;
            }
        }
        Buckets { ptr, items }
    }

    /// Number of buckets.
    pub fn n_buckets(&self) -> usize {
        self.ptr.len() - 1
    }

    /// The items of bucket `b`.
    #[inline]
    pub fn get(&self, b: usize) -> &[u32] {
        &self.items[self.ptr[b] as usize..self.ptr[b + 1] as usize]
    }
}

/// The offset table of a bucket table (the counts' prefix sums) whose item entries fall into
/// the buckets `keys` names, one entry each: `n_buckets + 1` offsets from 0. For items already
/// sorted by bucket, bucket `b` holds `ptr[b]..ptr[b + 1]`.
pub fn offsets(n_buckets: usize, keys: impl IntoIterator<Item = usize>) -> Vec<u32> {
    let mut ptr = vec![0u32; n_buckets + 1];
    for b in keys {
        ptr[b + 1] += 1;
    }
    for b in 0..n_buckets {
        ptr[b + 1] += ptr[b];
    }
    ptr
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn buckets_hold_their_items_in_order() {
        // Item t goes into buckets t % 3 and 3 (a shared one).
        let b = Buckets::build(4, 7, |t| [t % 3, 3]);
        assert_eq!(b.n_buckets(), 4);
        assert_eq!(b.get(0), &[0, 3, 6]);
        assert_eq!(b.get(1), &[1, 4]);
        assert_eq!(b.get(2), &[2, 5]);
        assert_eq!(b.get(3), &[0, 1, 2, 3, 4, 5, 6]);
        assert_eq!(offsets(3, [0, 0, 2]), vec![0, 2, 2, 3]);
        assert_eq!(Buckets::build(2, 0, |_| [0]).ptr, vec![0, 0, 0]);
    }
}
