//! A slab pool for brick planes, in 2 MiB chunks backed by huge pages.
//!
//! A render decodes thousands of bricks, and each brick's planes (16-bit
//! words: 72 KiB for a brick of 32^3 cells; codes: 32 KiB; f32 values:
//! 144 KiB) used to be fresh memory from the kernel: one page fault, one
//! page clearing and one memory-cgroup charge per 4 KiB page, about 69,000
//! faults for the first 1024^2 frame of a 1024^3 volume, and a quarter of
//! its time in the kernel (docs/BENCHMARKS.md, "Brick planes from a
//! pool"). [`PlanePool`] serves allocations of [`MIN`] to [`MAX`] bytes
//! from chunks of [`CHUNK`] bytes, aligned to 2 MiB and marked
//! `MADV_HUGEPAGE`, so where transparent huge pages are enabled (`always`
//! or `madvise`) a chunk is one fault. A class's first [`SMALL_CHUNKS`]
//! chunks stay on ordinary pages, so a small render does not clear 2 MiB
//! for every class it puts a few planes in. A huge page's first touch is
//! timed: where one took longer than [`SLOW_HUGE`] (on a virtual machine
//! whose host has taken the memory back, or where the kernel had to
//! compact memory for it), the next [`SMALL_AFTER_SLOW`] chunks, or more
//! after further slow ones, stay on ordinary pages. A freed slot is
//! reused by the next allocation of its size class without the kernel; a
//! chunk whose slots are all free is returned to the system unless it is
//! its class's only chunk with free slots, so memory still follows the
//! brick cache's budget (the aim of [`super::bound_heap_fragmentation`]).
//!
//! The command-line binary installs it as the global allocator
//! (`src/main.rs`); the library does not, so programs that link cdvol keep
//! their own. Every other allocation goes to the system allocator.
//!
//! Layout of a chunk: one 4 KiB page of `Header`, then slots of a whole
//! number of pages, so every slot is page-aligned. A slot's size class is
//! its size rounded up to pages; `dealloc` finds the class from the
//! `Layout` (the same one `alloc` got) and the chunk from the address.

use std::alloc::{GlobalAlloc, Layout, System};
use std::ptr::{self, null_mut};
use std::sync::{Mutex, OnceLock};
use std::time::{Duration, Instant};

/// Bytes of a chunk: the size of an x86-64 huge page.
pub const CHUNK: usize = 2 << 20;
/// Smallest allocation the pool takes: a brick's code plane of 32^3 cells.
pub const MIN: usize = 32 << 10;
/// Largest allocation the pool takes. Above it a chunk holds too few slots
/// (7 of 256 KiB); such buffers go to the system allocator.
pub const MAX: usize = 256 << 10;
const PAGE: usize = 4096;
/// Size classes: slots of 1 to `MAX / PAGE` pages (index = pages).
const CLASSES: usize = MAX / PAGE + 1;
/// A class's first chunks stay on ordinary pages; later ones ask for a
/// huge page. A huge page is cleared whole at its first touch, so a small
/// render that fills a few slots of each class would pay for 2 MiB per
/// class it barely uses: a third of a 1 x 1 render's CPU time
/// (docs/BENCHMARKS.md, "Huge pages only for a class's later chunks").
pub const SMALL_CHUNKS: usize = 4;
/// A huge page whose first touch took longer than this cost more than the
/// same chunk on ordinary pages would have (512 faults, about 1 ms on the
/// machine measured). There a huge page's first touch took about 0.17 ms
/// where the memory under it was backed, and 4.5 ms on this virtual
/// machine where its host had taken the guest's free 2 MiB blocks back
/// (free page reporting), as it does a few seconds after a process frees
/// them: a 1024^3 first frame after six idle seconds took 0.61-0.72 s with
/// huge pages and 0.37-0.41 s without (docs/BENCHMARKS.md, "Huge pages
/// only while they are fast").
pub const SLOW_HUGE: Duration = Duration::from_millis(1);
/// After a huge page slower than [`SLOW_HUGE`], the pool's next chunks that
/// would have asked for one stay on ordinary pages: this many after the
/// first slow one, twice as many after each further slow one in a row, up
/// to [`SMALL_AFTER_SLOW_MAX`]; a fast one resets it. So where all huge
/// pages are slow, about one chunk in 65 pays for a slow one (4.5 ms
/// against 1 ms), and where one slow block sits among fast ones, few
/// chunks lose their huge page.
pub const SMALL_AFTER_SLOW: usize = 8;
/// The most chunks kept on ordinary pages after a slow huge page.
pub const SMALL_AFTER_SLOW_MAX: usize = 64;

/// See [`PlanePool::register`].
static REGISTERED: OnceLock<&'static PlanePool> = OnceLock::new();

/// The first page of every chunk.
#[repr(C)]
struct Header {
    /// Pages per slot (the size class).
    pages: usize,
    /// Slots handed out and not yet freed.
    live: usize,
    /// Slots ever handed out from the chunk's untouched end: slots at and
    /// above this index have never been used.
    bump: usize,
    /// Freed slots, each holding the address of the next in its first
    /// bytes (null ends the list).
    free: *mut u8,
    /// The class's chunks with free slots, doubly linked (null ends).
    prev: *mut Header,
    next: *mut Header,
    /// Whether the chunk is in that list.
    listed: bool,
}

impl Header {
    fn slots(&self) -> usize {
        (CHUNK - PAGE) / (self.pages * PAGE)
    }

    fn has_room(&self) -> bool {
        !self.free.is_null() || self.bump < self.slots()
    }
}

/// Per class, the head of its list of chunks with free slots.
struct State {
    partial: [*mut Header; CLASSES],
    /// Chunks currently mapped (the tests check what is returned).
    chunks: usize,
    /// Per class, chunks ever mapped (see [`SMALL_CHUNKS`]).
    made: [usize; CLASSES],
    /// Chunks still to map on ordinary pages after a slow huge page, and
    /// how many the next slow one sets ([`SMALL_AFTER_SLOW`]).
    small_for: usize,
    backoff: usize,
    /// Chunks mapped onto huge pages, and how many of those were slow.
    huge: usize,
    slow: usize,
}

impl State {
    /// Whether the next chunk of class `pages` asks for a huge page: not
    /// for a class's first [`SMALL_CHUNKS`], nor while `small_for` lasts
    /// (which this counts down).
    fn wants_huge(&mut self, pages: usize) -> bool {
        if self.made[pages] < SMALL_CHUNKS {
            return false;
        }
        if self.small_for > 0 {
            self.small_for -= 1;
            return false;
        }
        true
    }

    /// A chunk that asked for a huge page took `took` at its first touch.
    fn touched_huge(&mut self, took: Duration) {
        self.huge += 1;
        if took > SLOW_HUGE {
            self.slow += 1;
            self.small_for = self.backoff;
            self.backoff = (2 * self.backoff).min(SMALL_AFTER_SLOW_MAX);
        } else {
            self.backoff = SMALL_AFTER_SLOW;
        }
    }
}

// SAFETY: the raw pointers are only touched under the pool's mutex.
unsafe impl Send for State {}

/// The slab pool; see the module documentation. `const`-constructible so
/// that it can be a `#[global_allocator]`.
pub struct PlanePool {
    state: Mutex<State>,
}

impl Default for PlanePool {
    fn default() -> Self {
        Self::new()
    }
}

impl PlanePool {
    pub const fn new() -> PlanePool {
        PlanePool {
            state: Mutex::new(State {
                partial: [null_mut(); CLASSES],
                chunks: 0,
                made: [0; CLASSES],
                small_for: 0,
                backoff: SMALL_AFTER_SLOW,
                huge: 0,
                slow: 0,
            }),
        }
    }

    /// The size class (pages per slot) of `layout`, if the pool serves it.
    pub fn class(layout: Layout) -> Option<usize> {
        let served = (MIN..=MAX).contains(&layout.size()) && layout.align() <= PAGE;
        served.then(|| layout.size().div_ceil(PAGE))
    }

    /// Chunks currently mapped.
    pub fn chunks(&self) -> usize {
        self.lock().chunks
    }

    /// Chunks ever mapped that asked for a huge page, and how many of
    /// those were slower than [`SLOW_HUGE`] at their first touch.
    pub fn huge_chunks(&self) -> (usize, usize) {
        let st = self.lock();
        (st.huge, st.slow)
    }

    /// Makes this pool the one [`PlanePool::registered`] returns: a
    /// binary that installs it as its global allocator registers it, so
    /// that a render's statistics can report its huge pages. The first
    /// registration stands; later ones are ignored.
    pub fn register(&'static self) {
        let _ = REGISTERED.set(self);
    }

    /// The pool [`PlanePool::register`] named, if any.
    pub fn registered() -> Option<&'static PlanePool> {
        REGISTERED.get().copied()
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, State> {
        // A panic while the lock is held cannot leave the lists half
        // changed (no code under the lock panics), so a poisoned lock is
        // still consistent.
        self.state.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// A slot of `pages` pages, or null if the system has no memory.
    fn take(&self, pages: usize) -> *mut u8 {
        let mut st = self.lock();
        let mut h = st.partial[pages];
        if h.is_null() {
            let huge = st.wants_huge(pages);
            // Mapped and first touched without the lock: the kernel's
            // clearing of a huge page takes 0.17-4.5 ms ([`SLOW_HUGE`]),
            // which other threads' allocations need not wait for. The
            // chunk is this thread's until it is pushed.
            drop(st);
            let took;
            (h, took) = new_chunk(pages, huge);
            if h.is_null() {
                return null_mut();
            }
            st = self.lock();
            if huge {
                st.touched_huge(took);
            }
            st.chunks += 1;
            st.made[pages] += 1;
            // SAFETY: `h` is a fresh chunk's header, not in any list; it
            // goes to the head of its class's list, with room.
            unsafe { push(&mut st, h) };
        }
        // SAFETY: `h` is a mapped chunk of this class with room (only such
        // chunks are listed); its header and slots are ours under the lock.
        unsafe {
            let slot = if (*h).free.is_null() {
                let s = (h as *mut u8).add(PAGE + (*h).bump * (*h).pages * PAGE);
                (*h).bump += 1;
                s
            } else {
                let s = (*h).free;
                (*h).free = ptr::read(s as *const *mut u8);
                s
            };
            (*h).live += 1;
            if !(*h).has_room() {
                unlink(&mut st, h);
            }
            slot
        }
    }

    /// Returns `slot` (from [`take`](Self::take) with `pages`).
    ///
    /// # Safety
    /// `slot` came from `take(pages)` of this pool and is not used again.
    unsafe fn give(&self, slot: *mut u8, pages: usize) {
        let h = (slot as usize & !(CHUNK - 1)) as *mut Header;
        let mut st = self.lock();
        // SAFETY: the chunk holding `slot` is mapped (it has a live slot)
        // and its header is ours under the lock. The header is reached
        // through `h` each time, never through a reference kept across
        // `push` and `unlink`, which write it too.
        unsafe {
            // A slot returned to another class breaks the caller's
            // contract; in debug builds, stop at once (a panic would
            // unwind out of `dealloc`, which is undefined behaviour).
            if cfg!(debug_assertions) && (*h).pages != pages {
                std::process::abort();
            }
            ptr::write(slot as *mut *mut u8, (*h).free);
            (*h).free = slot;
            (*h).live -= 1;
            if !(*h).listed {
                push(&mut st, h);
            }
            // An empty chunk goes back to the system unless it is the
            // class's only one with room (then the next brick reuses it).
            let only = st.partial[pages] == h && (*h).next.is_null();
            if (*h).live == 0 && !only {
                unlink(&mut st, h);
                st.chunks -= 1;
                drop(st);
                unmap(h as *mut u8, CHUNK);
            }
        }
    }
}

/// Adds `h` at the head of its class's list.
///
/// # Safety
/// `h` is a mapped chunk's header, not in the list; the lock is held.
unsafe fn push(st: &mut State, h: *mut Header) {
    // SAFETY: as the caller promises; the old head is a mapped header.
    unsafe {
        let c = &mut *h;
        let head = st.partial[c.pages];
        c.prev = null_mut();
        c.next = head;
        c.listed = true;
        if !head.is_null() {
            (*head).prev = h;
        }
        st.partial[c.pages] = h;
    }
}

/// Removes `h` from its class's list.
///
/// # Safety
/// `h` is a mapped chunk's header in the list; the lock is held.
unsafe fn unlink(st: &mut State, h: *mut Header) {
    // SAFETY: as the caller promises; its neighbours are mapped headers.
    unsafe {
        let c = &mut *h;
        if c.prev.is_null() {
            st.partial[c.pages] = c.next;
        } else {
            (*c.prev).next = c.next;
        }
        if !c.next.is_null() {
            (*c.next).prev = c.prev;
        }
        c.prev = null_mut();
        c.next = null_mut();
        c.listed = false;
    }
}

/// A new chunk for slots of `pages` pages, aligned to [`CHUNK`] and
/// advised onto a huge page when `huge`, its header written; null if the
/// system refuses the mapping. Also how long the header's write took: the
/// chunk's first touch, where the kernel maps (and clears) the huge page.
fn new_chunk(pages: usize, huge: bool) -> (*mut Header, Duration) {
    // Map twice the size and trim to an aligned chunk.
    // SAFETY: an anonymous private mapping at an address of the kernel's
    // choice; the result is checked.
    let raw = unsafe {
        libc::mmap(
            null_mut(),
            2 * CHUNK,
            libc::PROT_READ | libc::PROT_WRITE,
            libc::MAP_PRIVATE | libc::MAP_ANONYMOUS,
            -1,
            0,
        )
    };
    if raw == libc::MAP_FAILED {
        return (null_mut(), Duration::ZERO);
    }
    let raw = raw as usize;
    let base = (raw + CHUNK - 1) & !(CHUNK - 1);
    // SAFETY: both trimmed pieces lie in the mapping just made and hold
    // nothing.
    unsafe {
        unmap(raw as *mut u8, base - raw);
        unmap((base + CHUNK) as *mut u8, raw + 2 * CHUNK - base - CHUNK);
        // Advice only: where huge pages are off it fails, and the chunk
        // is 512 ordinary pages.
        if huge {
            libc::madvise(base as *mut libc::c_void, CHUNK, libc::MADV_HUGEPAGE);
        }
        let h = base as *mut Header;
        // The clock reads without allocating (a vDSO call on Linux).
        let start = Instant::now();
        ptr::write(
            h,
            Header {
                pages,
                live: 0,
                bump: 0,
                free: null_mut(),
                prev: null_mut(),
                next: null_mut(),
                listed: false,
            },
        );
        (h, start.elapsed())
    }
}

/// Unmaps `len` bytes at `p` (nothing for 0).
///
/// # Safety
/// The range is mapped and nothing in it is used again.
unsafe fn unmap(p: *mut u8, len: usize) {
    if len > 0 {
        // SAFETY: as the caller promises. A failure would leave the range
        // mapped (a leak, not a fault), so it is not checked.
        unsafe { libc::munmap(p as *mut libc::c_void, len) };
    }
}

// SAFETY: `alloc` returns page-aligned slots of at least the layout's size
// (classes round up to pages, and the pool takes only alignments up to a
// page) or the system allocator's memory; `dealloc` routes by the same
// layout test, so each pointer returns to the allocator it came from.
unsafe impl GlobalAlloc for PlanePool {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        match Self::class(layout) {
            Some(pages) => self.take(pages),
            // SAFETY: the caller's layout contract, passed on.
            None => unsafe { System.alloc(layout) },
        }
    }

    unsafe fn dealloc(&self, p: *mut u8, layout: Layout) {
        match Self::class(layout) {
            // SAFETY: `p` came from `alloc` with this layout, so from
            // `take` with this class.
            Some(pages) => unsafe { self.give(p, pages) },
            // SAFETY: likewise from the system allocator.
            None => unsafe { System.dealloc(p, layout) },
        }
    }

    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        match Self::class(layout) {
            Some(pages) => {
                let p = self.take(pages);
                if !p.is_null() {
                    // SAFETY: a slot of at least `layout.size()` bytes.
                    unsafe { ptr::write_bytes(p, 0, layout.size()) };
                }
                p
            }
            // SAFETY: the caller's layout contract, passed on.
            None => unsafe { System.alloc_zeroed(layout) },
        }
    }

    unsafe fn realloc(&self, p: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        // SAFETY (all arms): the caller's contract for `p`, `layout` and
        // `new_size` (non-zero, fits isize with the alignment).
        let new = unsafe { Layout::from_size_align_unchecked(new_size, layout.align()) };
        match (Self::class(layout), Self::class(new)) {
            (None, None) => unsafe { System.realloc(p, layout, new_size) },
            // The slot already has room for the new size.
            (Some(a), Some(b)) if a == b => p,
            _ => unsafe {
                let q = self.alloc(new);
                if !q.is_null() {
                    ptr::copy_nonoverlapping(p, q, layout.size().min(new_size));
                    self.dealloc(p, layout);
                }
                q
            },
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn layout(size: usize, align: usize) -> Layout {
        Layout::from_size_align(size, align).unwrap()
    }

    #[test]
    fn classes() {
        assert_eq!(PlanePool::class(layout(MIN - 1, 8)), None);
        assert_eq!(PlanePool::class(layout(MIN, 8)), Some(8));
        assert_eq!(PlanePool::class(layout(MIN + 1, 8)), Some(9));
        assert_eq!(PlanePool::class(layout(72 * 1024 + 2, 2)), Some(19));
        assert_eq!(PlanePool::class(layout(MAX, 4)), Some(64));
        assert_eq!(PlanePool::class(layout(MAX + 1, 4)), None);
        assert_eq!(PlanePool::class(layout(MIN, 2 * PAGE)), None);
    }

    /// A slot's chunk is found from its address, slots are page-aligned,
    /// freed slots are reused before new ones, and a chunk whose slots
    /// are all free is unmapped unless it is its class's last with room.
    #[test]
    fn reuse_and_return() {
        let pool = PlanePool::new();
        let l = layout(72 * 1024, 2);
        let per_chunk = (CHUNK - PAGE) / (18 * PAGE);
        let ps: Vec<*mut u8> = (0..per_chunk + 1)
            .map(|_| unsafe { pool.alloc(l) })
            .collect();
        assert!(ps
            .iter()
            .all(|p| !p.is_null() && (*p as usize).is_multiple_of(PAGE)));
        assert_eq!(pool.chunks(), 2);
        let (a, b) = (
            ps[0] as usize & !(CHUNK - 1),
            ps[per_chunk] as usize & !(CHUNK - 1),
        );
        assert_ne!(a, b);
        assert!(ps[..per_chunk]
            .iter()
            .all(|&p| p as usize & !(CHUNK - 1) == a));
        unsafe {
            pool.dealloc(ps[3], l);
            assert_eq!(pool.alloc(l), ps[3], "a freed slot is reused");
            for &p in &ps[..per_chunk] {
                pool.dealloc(p, l);
            }
        }
        // The first chunk emptied while the second still had room.
        assert_eq!(pool.chunks(), 1);
        unsafe { pool.dealloc(ps[per_chunk], l) };
        // The last chunk with room stays for the next brick.
        assert_eq!(pool.chunks(), 1);
        let p = unsafe { pool.alloc(l) };
        assert_eq!(p as usize & !(CHUNK - 1), b);
        unsafe { pool.dealloc(p, l) };
    }

    /// `VmFlags` of the mapping that holds `addr`, from /proc/self/smaps.
    fn vm_flags(addr: usize) -> String {
        let smaps = std::fs::read_to_string("/proc/self/smaps").unwrap();
        let mut inside = false;
        for line in smaps.lines() {
            let range = line.split_whitespace().next().unwrap_or("");
            if let Some((a, b)) = range.split_once('-') {
                if let (Ok(a), Ok(b)) = (usize::from_str_radix(a, 16), usize::from_str_radix(b, 16))
                {
                    inside = (a..b).contains(&addr);
                    continue;
                }
            }
            if let (true, Some(f)) = (inside, line.strip_prefix("VmFlags:")) {
                return f.trim().to_string();
            }
        }
        panic!("no mapping holds {addr:#x}");
    }

    /// A class's first [`SMALL_CHUNKS`] chunks are not advised onto huge
    /// pages; the next one is (`hg` in its `VmFlags`), where the kernel
    /// has transparent huge pages at all.
    #[test]
    fn huge_pages_only_after_the_first_chunks() {
        let pool = PlanePool::new();
        let l = layout(40 * 1024, 8);
        let per_chunk = (CHUNK - PAGE) / (10 * PAGE);
        let ps: Vec<*mut u8> = (0..SMALL_CHUNKS * per_chunk + 1)
            .map(|_| unsafe { pool.alloc(l) })
            .collect();
        assert!(ps.iter().all(|p| !p.is_null()));
        assert_eq!(pool.chunks(), SMALL_CHUNKS + 1);
        for c in 0..SMALL_CHUNKS {
            let f = vm_flags(ps[c * per_chunk] as usize);
            assert!(!f.split(' ').any(|x| x == "hg"), "chunk {c}: {f}");
        }
        if std::path::Path::new("/sys/kernel/mm/transparent_hugepage").exists() {
            let f = vm_flags(*ps.last().unwrap() as usize);
            assert!(f.split(' ').any(|x| x == "hg"), "the later chunk: {f}");
        }
        assert_eq!(pool.huge_chunks().0, 1);
        for p in ps {
            unsafe { pool.dealloc(p, l) };
        }
    }

    /// After a huge page slower than [`SLOW_HUGE`], the next
    /// [`SMALL_AFTER_SLOW`] chunks that would have asked for one stay on
    /// ordinary pages and the one after them asks again; each further slow
    /// one in a row doubles the wait up to [`SMALL_AFTER_SLOW_MAX`], and a
    /// fast one resets it. A huge page as slow as the limit, or a class's
    /// first chunks, change nothing.
    #[test]
    fn slow_huge_pages_keep_the_next_chunks_on_ordinary_pages() {
        let pool = PlanePool::new();
        let mut st = pool.lock();
        let c = 10;
        for _ in 0..SMALL_CHUNKS {
            assert!(!st.wants_huge(c));
            st.made[c] += 1;
        }
        // Chunks on ordinary pages until the next one asks for a huge page.
        let wait = |st: &mut State| (0..).find(|_| st.wants_huge(c)).unwrap_or(0);
        assert_eq!(wait(&mut st), 0);
        st.touched_huge(SLOW_HUGE);
        assert_eq!(wait(&mut st), 0);
        let slow = SLOW_HUGE + Duration::from_nanos(1);
        let mut waits = Vec::new();
        for _ in 0..5 {
            st.touched_huge(slow);
            // Another class's first chunks neither ask nor count down.
            assert!(!st.wants_huge(c + 1));
            waits.push(wait(&mut st));
        }
        st.touched_huge(Duration::ZERO);
        waits.push(wait(&mut st));
        st.touched_huge(slow);
        waits.push(wait(&mut st));
        let s = SMALL_AFTER_SLOW;
        assert_eq!(waits, [s, 2 * s, 4 * s, 8 * s, SMALL_AFTER_SLOW_MAX, 0, s]);
        assert_eq!(8 * s, SMALL_AFTER_SLOW_MAX);
        assert_eq!((st.huge, st.slow), (8, 6));
    }

    #[test]
    fn zeroed_realloc_and_the_system_route() {
        let pool = PlanePool::new();
        unsafe {
            let l = layout(40_000, 4);
            let p = pool.alloc(l);
            ptr::write_bytes(p, 0xAB, l.size());
            pool.dealloc(p, l);
            // The same slot again, cleared.
            let z = pool.alloc_zeroed(l);
            assert_eq!(z, p);
            assert!(std::slice::from_raw_parts(z, l.size())
                .iter()
                .all(|&b| b == 0));
            // Within the class: the same slot; out of it: moved, bytes kept.
            *z = 7;
            assert_eq!(pool.realloc(z, l, 40_900), z);
            let big = pool.realloc(z, layout(40_900, 4), 300_000);
            assert_eq!(*big, 7);
            let small = pool.realloc(big, layout(300_000, 4), 100);
            assert_eq!(*small, 7);
            pool.dealloc(small, layout(100, 4));
        }
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(64))]
        /// Random interleavings of allocations (pool sizes and others,
        /// several classes) and frees: every block keeps its own bytes
        /// and no two live blocks overlap; at the end at most one chunk
        /// per class is still mapped.
        #[test]
        fn blocks_never_overlap(ops in prop::collection::vec((0usize..6, 0u8..3, any::<u8>()), 1..300)) {
            let pool = PlanePool::new();
            let sizes = [100, MIN, 72 * 1024 + 2, 144 * 1024, MAX, MAX + 4096];
            let mut live: Vec<(*mut u8, Layout, u8)> = Vec::new();
            for (s, op, fill) in ops {
                if op < 2 || live.is_empty() {
                    let l = layout(sizes[s], 4);
                    let p = unsafe { pool.alloc(l) };
                    prop_assert!(!p.is_null());
                    unsafe { ptr::write_bytes(p, fill, l.size()) };
                    live.push((p, l, fill));
                } else {
                    let (p, l, fill) = live.swap_remove(fill as usize % live.len());
                    let bytes = unsafe { std::slice::from_raw_parts(p, l.size()) };
                    prop_assert!(bytes.iter().all(|&b| b == fill), "a block was overwritten");
                    unsafe { pool.dealloc(p, l) };
                }
            }
            for &(p, l, fill) in &live {
                let bytes = unsafe { std::slice::from_raw_parts(p, l.size()) };
                prop_assert!(bytes.iter().all(|&b| b == fill), "a block was overwritten");
                unsafe { pool.dealloc(p, l) };
            }
            prop_assert!(pool.chunks() <= 4, "{} chunks left", pool.chunks());
        }
    }

    /// Two threads allocating and freeing at once see their own bytes.
    #[test]
    fn threads() {
        let pool = std::sync::Arc::new(PlanePool::new());
        let hs: Vec<_> = (0..2u8)
            .map(|t| {
                let pool = std::sync::Arc::clone(&pool);
                std::thread::spawn(move || {
                    let l = layout(MIN + 4096 * t as usize, 8);
                    for round in 0..200u32 {
                        let ps: Vec<_> = (0..20).map(|_| unsafe { pool.alloc(l) }).collect();
                        for &p in &ps {
                            unsafe { ptr::write_bytes(p, t ^ round as u8, l.size()) };
                        }
                        for &p in &ps {
                            let b = unsafe { std::slice::from_raw_parts(p, l.size()) };
                            assert!(b.iter().all(|&x| x == t ^ round as u8));
                            unsafe { pool.dealloc(p, l) };
                        }
                    }
                })
            })
            .collect();
        for h in hs {
            h.join().unwrap();
        }
        assert!(pool.chunks() <= 2);
    }
}
