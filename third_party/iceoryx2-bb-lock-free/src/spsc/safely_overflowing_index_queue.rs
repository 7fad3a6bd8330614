// Copyright (c) 2023 Contributors to the Eclipse Foundation
//
// See the NOTICE file(s) distributed with this work for additional
// information regarding copyright ownership.
//
// This program and the accompanying materials are made available under the
// terms of the Apache Software License 2.0 which is available at
// https://www.apache.org/licenses/LICENSE-2.0, or the MIT license
// which is available at https://opensource.org/licenses/MIT.
//
// SPDX-License-Identifier: Apache-2.0 OR MIT

//! A **threadsafe** **lock-free** single producer single consumer queue which can store [`usize`]
//! integers or indices with overflow behavior. When the queue is full the oldest element is
//! returned to the producer and replaced with the newest.
//!
//! # Example
//!
//! ```
//! # extern crate iceoryx2_bb_loggers;
//!
//! use iceoryx2_bb_lock_free::spsc::safely_overflowing_index_queue::*;
//!
//! const QUEUE_CAPACITY: usize = 128;
//! let queue = FixedSizeSafelyOverflowingIndexQueue::<QUEUE_CAPACITY>::new();
//!
//! let mut producer = match queue.acquire_producer() {
//!     None => panic!("a producer has been already acquired."),
//!     Some(p) => p,
//! };
//!
//! match producer.push(1234) {
//!     Some(e) => println!("queue is full, recycled element {}", e),
//!     None => println!("add element to queue")
//! }
//!
//! let mut consumer = match queue.acquire_consumer() {
//!     None => panic!("a consumer has been already acquired."),
//!     Some(p) => p,
//! };
//!
//! match consumer.pop() {
//!     None => println!("queue is empty"),
//!     Some(v) => println!("got {}", v)
//! }
//! ```

use core::{alloc::Layout, fmt::Debug};

use iceoryx2_bb_concurrency::atomic::AtomicBool;
use iceoryx2_bb_concurrency::atomic::AtomicU64;
use iceoryx2_bb_concurrency::atomic::Ordering;
use iceoryx2_bb_concurrency::cell::UnsafeCell;
use iceoryx2_bb_elementary::math::unaligned_mem_size;
use iceoryx2_bb_elementary::owning_pointer::OwningPointer;
use iceoryx2_bb_elementary::{
    bump_allocator::BumpAllocator, relocatable_pointer::RelocatablePointer,
};
use iceoryx2_bb_elementary_traits::{
    pointer::Pointer, relocatable_container::RelocatableContainer,
};
use iceoryx2_log::{fail, fatal_panic};

/// The [`Producer`] of the [`SafelyOverflowingIndexQueue`]/[`FixedSizeSafelyOverflowingIndexQueue`]
/// which can add values to it via [`Producer::push()`].
#[derive(Debug)]
pub struct Producer<'a, PointerType: Pointer<UnsafeCell<u64>>> {
    queue: &'a details::SafelyOverflowingIndexQueue<PointerType>,
}

impl<PointerType: Pointer<UnsafeCell<u64>> + Debug> Producer<'_, PointerType> {
    /// Adds a new value to the [`SafelyOverflowingIndexQueue`]/[`FixedSizeSafelyOverflowingIndexQueue`].
    /// If the queue is full it returns the oldest index.
    pub fn push(&mut self, t: u64) -> Option<u64> {
        unsafe { self.queue.push(t) }
    }
}

impl<PointerType: Pointer<UnsafeCell<u64>>> Drop for Producer<'_, PointerType> {
    fn drop(&mut self) {
        self.queue.has_producer.store(
            true,
            // SYNC POINT: producer
            // sync the internal state with the next producer in another thread
            Ordering::Release,
        );
    }
}

/// The [`Consumer`] of the [`SafelyOverflowingIndexQueue`]/[`FixedSizeSafelyOverflowingIndexQueue`]
/// which can acquire values from it via [`Consumer::pop()`].
#[derive(Debug)]
pub struct Consumer<'a, PointerType: Pointer<UnsafeCell<u64>>> {
    queue: &'a details::SafelyOverflowingIndexQueue<PointerType>,
}

impl<PointerType: Pointer<UnsafeCell<u64>> + Debug> Consumer<'_, PointerType> {
    /// Acquires a value from the [`SafelyOverflowingIndexQueue`]/[`FixedSizeSafelyOverflowingIndexQueue`].
    /// If the queue is empty it returns [`None`] otherwise the value.
    pub fn pop(&mut self) -> Option<u64> {
        unsafe { self.queue.pop() }
    }
}

impl<PointerType: Pointer<UnsafeCell<u64>>> Drop for Consumer<'_, PointerType> {
    fn drop(&mut self) {
        self.queue.has_consumer.store(
            true,
            // SYNC POINT: consumer
            // sync the internal state with the next consumer in another thread
            Ordering::Release,
        );
    }
}

/// Non-relocatable version of the safely overflowing index queue
pub type SafelyOverflowingIndexQueue =
    details::SafelyOverflowingIndexQueue<OwningPointer<UnsafeCell<u64>>>;

/// Relocatable version of the safely overflowing index queue
pub type RelocatableSafelyOverflowingIndexQueue =
    details::SafelyOverflowingIndexQueue<RelocatablePointer<UnsafeCell<u64>>>;

pub mod details {
    use core::ptr::NonNull;
    use iceoryx2_bb_elementary_traits::zero_copy_send::ZeroCopySend;

    use super::*;

    /// A threadsafe lock-free safely overflowing index queue with a capacity which can be set up at runtime,
    /// when the queue is created. When the queue is full the oldest element is returned to the producer
    /// and overridden with the newest element.
    #[derive(Debug)]
    #[repr(C)]
    pub struct SafelyOverflowingIndexQueue<PointerType: Pointer<UnsafeCell<u64>>> {
        data_ptr: PointerType,
        pub(super) has_producer: AtomicBool,
        pub(super) has_consumer: AtomicBool,
        is_memory_initialized: AtomicBool,
        capacity: usize,
        write_position: AtomicU64,
        read_position: AtomicU64,
    }

    unsafe impl<PointerType: Pointer<UnsafeCell<u64>> + ZeroCopySend> ZeroCopySend
        for SafelyOverflowingIndexQueue<PointerType>
    {
    }
    unsafe impl<PointerType: Pointer<UnsafeCell<u64>>> Sync
        for SafelyOverflowingIndexQueue<PointerType>
    {
    }
    unsafe impl<PointerType: Pointer<UnsafeCell<u64>>> Send
        for SafelyOverflowingIndexQueue<PointerType>
    {
    }

    impl SafelyOverflowingIndexQueue<OwningPointer<UnsafeCell<u64>>> {
        pub fn new(capacity: usize) -> Self {
            let mut data_ptr = OwningPointer::<UnsafeCell<u64>>::new_with_alloc(capacity + 1);

            for i in 0..capacity + 1 {
                unsafe { data_ptr.as_mut_ptr().add(i).write(UnsafeCell::new(0)) };
            }

            Self {
                data_ptr,
                capacity,
                write_position: AtomicU64::new(0),
                read_position: AtomicU64::new(0),
                has_producer: AtomicBool::new(true),
                has_consumer: AtomicBool::new(true),
                is_memory_initialized: AtomicBool::new(true),
            }
        }
    }

    impl RelocatableContainer for SafelyOverflowingIndexQueue<RelocatablePointer<UnsafeCell<u64>>> {
        unsafe fn new_uninit(capacity: usize) -> Self {
            unsafe {
                Self {
                    data_ptr: RelocatablePointer::new_uninit(),
                    capacity,
                    write_position: AtomicU64::new(0),
                    read_position: AtomicU64::new(0),
                    has_producer: AtomicBool::new(true),
                    has_consumer: AtomicBool::new(true),
                    is_memory_initialized: AtomicBool::new(false),
                }
            }
        }

        unsafe fn init<T: iceoryx2_bb_elementary_traits::allocator::Allocate<NonNull<u8>>>(
            &mut self,
            allocator: &T,
        ) -> Result<(), iceoryx2_bb_elementary_traits::allocator::AllocationError> {
            if self.is_memory_initialized.load(Ordering::Relaxed) {
                fatal_panic!(from self, "Memory already initialized. Initializing it twice may lead to undefined behavior.");
            }
            unsafe {
                self.data_ptr.init(fail!(from self, when allocator
            .allocate( Layout::from_size_align_unchecked(
                    core::mem::size_of::<u64>() * (self.capacity + 1),
                    core::mem::align_of::<u64>())),
            "Failed to initialize since the allocation of the data memory failed."));

                for i in 0..self.capacity + 1 {
                    (self.data_ptr.as_ptr() as *mut UnsafeCell<usize>)
                        .add(i)
                        .write(UnsafeCell::new(0));
                }
            }
            self.is_memory_initialized.store(true, Ordering::Relaxed);
            Ok(())
        }

        fn memory_size(capacity: usize) -> usize {
            Self::const_memory_size(capacity)
        }
    }

    impl<PointerType: Pointer<UnsafeCell<u64>> + Debug> SafelyOverflowingIndexQueue<PointerType> {
        #[inline(always)]
        fn verify_init(&self, source: &str) {
            debug_assert!(
                self.is_memory_initialized.load(Ordering::Relaxed),
                "Undefined behavior when calling SafelyOverflowingIndexQueue::{source} and the object is not initialized."
            );
        }

        /// Returns the amount of memory required to create a [`SafelyOverflowingIndexQueue`] with
        /// the provided capacity.
        pub const fn const_memory_size(capacity: usize) -> usize {
            unaligned_mem_size::<UnsafeCell<u64>>(capacity + 1)
        }

        fn at(&self, position: u64) -> *mut u64 {
            unsafe {
                (*self
                    .data_ptr
                    .as_ptr()
                    .add((position % (self.capacity as u64 + 1)) as usize))
                .get()
            }
        }
        /// Acquires the [`Producer`] of the [`SafelyOverflowingIndexQueue`]. This is threadsafe and
        /// lock-free without restrictions but when another thread has already acquired the [`Producer`]
        /// it returns [`None`] since it is a single producer single consumer
        /// [`SafelyOverflowingIndexQueue`].
        /// ```
        /// # extern crate iceoryx2_bb_loggers;
        ///
        /// use iceoryx2_bb_lock_free::spsc::safely_overflowing_index_queue::*;
        ///
        /// const QUEUE_CAPACITY: usize = 128;
        /// let queue = FixedSizeSafelyOverflowingIndexQueue::<QUEUE_CAPACITY>::new();
        ///
        /// let mut producer = match queue.acquire_producer() {
        ///     None => panic!("a producer has been already acquired."),
        ///     Some(p) => p,
        /// };
        ///
        /// match producer.push(1234) {
        ///     Some(e) => println!("queue is full, recycle element {}", e),
        ///     None => println!("added element to queue")
        /// }
        /// ```
        pub fn acquire_producer(&self) -> Option<Producer<'_, PointerType>> {
            self.verify_init("acquire_producer()");
            match self.has_producer.compare_exchange(
                true,
                false,
                // SYNC POINT: producer
                // sync the internal state with the next producer in another thread
                Ordering::Acquire,
                // the consumer could not be acquired therefore we do not need to sync anything
                Ordering::Relaxed,
            ) {
                Ok(_) => Some(Producer { queue: self }),
                Err(_) => None,
            }
        }
        /// Acquires the [`Consumer`] of the [`SafelyOverflowingIndexQueue`]. This is threadsafe and
        /// lock-free without restrictions but when another thread has already acquired the [`Consumer`]
        /// it returns [`None`] since it is a single producer single consumer
        /// [`SafelyOverflowingIndexQueue`].
        /// ```
        /// # extern crate iceoryx2_bb_loggers;
        ///
        /// use iceoryx2_bb_lock_free::spsc::safely_overflowing_index_queue::*;
        ///
        /// const QUEUE_CAPACITY: usize = 128;
        /// let queue = FixedSizeSafelyOverflowingIndexQueue::<QUEUE_CAPACITY>::new();
        ///
        /// let mut consumer = match queue.acquire_consumer() {
        ///     None => panic!("a consumer has been already acquired."),
        ///     Some(p) => p,
        /// };
        ///
        /// match consumer.pop() {
        ///     None => println!("queue is empty"),
        ///     Some(v) => println!("got {}", v)
        /// }
        /// ```
        pub fn acquire_consumer(&self) -> Option<Consumer<'_, PointerType>> {
            self.verify_init("acquire_consumer()");
            match self.has_consumer.compare_exchange(
                true,
                false,
                // SYNC POINT: consumer
                // sync the internal state with the next consumer in another thread
                Ordering::Acquire,
                // the consumer could not be acquired therefore we do not need to sync anything
                Ordering::Relaxed,
            ) {
                Ok(_) => Some(Consumer { queue: self }),
                Err(_) => None,
            }
        }

        /// Push an index into the [`SafelyOverflowingIndexQueue`]. If the queue is full the oldest
        /// index is returned and replaced with the new value.
        ///
        /// # Safety
        ///
        ///  * [`SafelyOverflowingIndexQueue::push()`] cannot be called concurrently. The user has
        ///    to ensure that at most one thread access this method.
        ///  * It has to be ensured that the memory is initialized with
        ///    [`SafelyOverflowingIndexQueue::init()`].
        pub unsafe fn push(&self, value: u64) -> Option<u64> {
            ////////////////
            // SYNC POINT R
            ////////////////
            // required when push in overflow case is called non-concurrently from a different
            // thread
            let write_position = self.write_position.load(Ordering::Acquire);
            let read_position = self.read_position.load(Ordering::Relaxed);
            let is_full = write_position == read_position + self.capacity as u64;

            unsafe { self.at(write_position).write(value) };

            ////////////////
            // SYNC POINT W
            ////////////////
            self.write_position
                .store(write_position + 1, Ordering::Release);

            if is_full
                && self
                    .read_position
                    .compare_exchange(
                        read_position,
                        read_position + 1,
                        ////////////////
                        // SYNC POINT R
                        ////////////////
                        Ordering::AcqRel,
                        Ordering::Relaxed,
                    )
                    .is_ok()
            {
                let value = unsafe { *self.at(read_position) };
                Some(value)
            } else {
                None
            }
        }

        /// Acquires an index from the [`SafelyOverflowingIndexQueue`]. If the queue is empty
        /// [`None`] is returned.
        ///
        /// # Safety
        ///
        ///  * [`SafelyOverflowingIndexQueue::pop()`] cannot be called concurrently. The user has
        ///    to ensure that at most one thread access this method.
        ///  * It has to be ensured that the memory is initialized with
        ///    [`SafelyOverflowingIndexQueue::init()`].
        pub unsafe fn pop(&self) -> Option<u64> {
            let mut read_position = self.read_position.load(Ordering::Relaxed);
            ////////////////
            // SYNC POINT W
            ////////////////
            let is_empty = read_position == self.write_position.load(Ordering::Acquire);

            if is_empty {
                return None;
            }

            let mut value;
            loop {
                value = unsafe { *self.at(read_position) };

                match self.read_position.compare_exchange(
                    read_position,
                    read_position + 1,
                    Ordering::Relaxed,
                    ////////////////
                    // SYNC POINT R
                    ////////////////
                    Ordering::Acquire,
                ) {
                    Ok(_) => break,
                    Err(v) => read_position = v,
                }
            }

            Some(value)
        }

        /// DEAR PATCH: where this queue's slots are, as its (shared, writable by the other side)
        /// relocatable pointer says; compare it with the address computed privately, then use
        /// [`SafelyOverflowingIndexQueue::dear_push()`].
        pub fn dear_data_address(&self) -> usize {
            self.data_ptr.as_ptr() as usize
        }

        /// DEAR PATCH: [`SafelyOverflowingIndexQueue::push()`] with the slots' address and the
        /// capacity given by the caller (kept privately; the queue has `capacity + 1` slots)
        /// instead of read from memory another process writes; wrapping position arithmetic.
        /// The returned (overflowed) value was stored in shared memory: validate it.
        ///
        /// # Safety
        ///
        ///   * as [`SafelyOverflowingIndexQueue::push()`]; `data` must point to `capacity + 1`
        ///     slots that stay mapped while this runs.
        pub unsafe fn dear_push(
            &self,
            data: *const UnsafeCell<u64>,
            capacity: usize,
            value: u64,
        ) -> Option<u64> {
            let slots = capacity as u64 + 1;
            let at = |position: u64| unsafe { (*data.add((position % slots) as usize)).get() };
            let write_position = self.write_position.load(Ordering::Acquire);
            let read_position = self.read_position.load(Ordering::Relaxed);
            let is_full = write_position == read_position.wrapping_add(capacity as u64);

            unsafe { core::ptr::write_volatile(at(write_position), value) };
            self.write_position
                .store(write_position.wrapping_add(1), Ordering::Release);

            if is_full
                && self
                    .read_position
                    .compare_exchange(
                        read_position,
                        read_position.wrapping_add(1),
                        Ordering::AcqRel,
                        Ordering::Relaxed,
                    )
                    .is_ok()
            {
                Some(unsafe { core::ptr::read_volatile(at(read_position)) })
            } else {
                None
            }
        }

        /// DEAR PATCH: [`SafelyOverflowingIndexQueue::pop()`] with the slots' address and the
        /// capacity given by the caller (kept privately; the queue has `capacity + 1` slots)
        /// instead of read from memory another process writes; wrapping position arithmetic,
        /// volatile slot reads, and at most `capacity + 2` tries when the position changes
        /// under it (the producer takes the oldest value on overflow; a process that keeps
        /// rewriting the position cannot keep the caller spinning: then `None`). The value was
        /// stored in shared memory: validate it.
        ///
        /// # Safety
        ///
        ///   * as [`SafelyOverflowingIndexQueue::pop()`]; `data` must point to `capacity + 1`
        ///     slots that stay mapped while this runs.
        pub unsafe fn dear_pop(&self, data: *const UnsafeCell<u64>, capacity: usize) -> Option<u64> {
            let slots = capacity as u64 + 1;
            let at = |position: u64| unsafe { (*data.add((position % slots) as usize)).get() };
            let mut read_position = self.read_position.load(Ordering::Relaxed);
            if read_position == self.write_position.load(Ordering::Acquire) {
                return None;
            }
            for _ in 0..capacity + 2 {
                let value = unsafe { core::ptr::read_volatile(at(read_position)) };
                match self.read_position.compare_exchange(
                    read_position,
                    read_position.wrapping_add(1),
                    Ordering::Relaxed,
                    Ordering::Acquire,
                ) {
                    Ok(_) => return Some(value),
                    Err(v) => read_position = v,
                }
            }
            None
        }

        /// DEAR PATCH: whether the positions describe at most `capacity + 1` queued values (the
        /// most a producer leaves while it overflows): false when another process rewrote
        /// them (every pop would then hand out old slot contents again).
        pub fn dear_positions_plausible(&self, capacity: usize) -> bool {
            let write_position = self.write_position.load(Ordering::Relaxed);
            let read_position = self.read_position.load(Ordering::Relaxed);
            write_position.wrapping_sub(read_position) <= capacity as u64 + 1
        }

        /// DEAR PATCH: [`SafelyOverflowingIndexQueue::is_empty()`] with one read of each
        /// position (no retry loop another process can keep spinning).
        pub fn dear_is_empty(&self) -> bool {
            self.write_position.load(Ordering::Relaxed) == self.read_position.load(Ordering::Relaxed)
        }

        /// DEAR PATCH: [`SafelyOverflowingIndexQueue::is_full()`] with the capacity kept
        /// privately; one read of each position (no retry loop another process can keep
        /// spinning), wrapping arithmetic.
        pub fn dear_is_full(&self, capacity: usize) -> bool {
            let write_position = self.write_position.load(Ordering::Relaxed);
            let read_position = self.read_position.load(Ordering::Relaxed);
            write_position == read_position.wrapping_add(capacity as u64)
        }

        fn acquire_read_and_write_position(&self) -> (u64, u64) {
            loop {
                let write_position = self.write_position.load(Ordering::Relaxed);
                let read_position = self.read_position.load(Ordering::Relaxed);

                if write_position == self.write_position.load(Ordering::Relaxed)
                    && read_position == self.read_position.load(Ordering::Relaxed)
                {
                    return (write_position, read_position);
                }
            }
        }

        /// Returns true when the [`SafelyOverflowingIndexQueue`] is empty, otherwise false.
        /// Note: This method may make only sense in a non-concurrent setup since the information
        ///       could be out-of-date as soon as it is acquired.
        pub fn is_empty(&self) -> bool {
            let (write_position, read_position) = self.acquire_read_and_write_position();
            write_position == read_position
        }

        /// Returns the length of the [`SafelyOverflowingIndexQueue`].
        /// Note: This method may make only sense in a non-concurrent setup since the information
        ///       could be out-of-date as soon as it is acquired.
        pub fn len(&self) -> usize {
            let (write_position, read_position) = self.acquire_read_and_write_position();
            (write_position - read_position) as usize
        }

        /// Returns the capacity of the [`SafelyOverflowingIndexQueue`].
        pub const fn capacity(&self) -> usize {
            self.capacity
        }

        /// Returns true when the [`SafelyOverflowingIndexQueue`] is full, otherwise false.
        /// Note: This method may make only sense in a non-concurrent setup since the information
        ///       could be out-of-date as soon as it is acquired.
        pub fn is_full(&self) -> bool {
            let (write_position, read_position) = self.acquire_read_and_write_position();
            write_position == read_position + self.capacity as u64
        }
    }
}

/// The compile-time fixed size version of the [`SafelyOverflowingIndexQueue`].
#[derive(Debug)]
#[repr(C)]
pub struct FixedSizeSafelyOverflowingIndexQueue<const CAPACITY: usize> {
    state: RelocatableSafelyOverflowingIndexQueue,
    data: [UnsafeCell<u64>; CAPACITY],
    data_plus_one: UnsafeCell<u64>,
}

unsafe impl<const CAPACITY: usize> Sync for FixedSizeSafelyOverflowingIndexQueue<CAPACITY> {}
unsafe impl<const CAPACITY: usize> Send for FixedSizeSafelyOverflowingIndexQueue<CAPACITY> {}

impl<const CAPACITY: usize> Default for FixedSizeSafelyOverflowingIndexQueue<CAPACITY> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const CAPACITY: usize> FixedSizeSafelyOverflowingIndexQueue<CAPACITY> {
    /// Creates a new empty [`FixedSizeSafelyOverflowingIndexQueue`].
    pub fn new() -> Self {
        let mut new_self = Self {
            state: unsafe { RelocatableSafelyOverflowingIndexQueue::new_uninit(CAPACITY) },
            data: [const { UnsafeCell::new(0) }; CAPACITY],
            data_plus_one: UnsafeCell::new(0),
        };

        // SAFETY: Creating a pointer to an existing member is always not null
        let data_ptr =
            unsafe { core::ptr::NonNull::<u8>::new_unchecked(new_self.data.as_mut_ptr().cast()) };

        let allocator = BumpAllocator::new(
            data_ptr,
            size_of::<Self>() - core::mem::offset_of!(Self, data),
        );
        unsafe {
            new_self
                .state
                .init(&allocator)
                .expect("All required memory is preallocated.")
        };

        new_self
    }

    /// See [`SafelyOverflowingIndexQueue::acquire_producer()`]
    pub fn acquire_producer(&self) -> Option<Producer<'_, RelocatablePointer<UnsafeCell<u64>>>> {
        self.state.acquire_producer()
    }

    /// See [`SafelyOverflowingIndexQueue::acquire_consumer()`]
    pub fn acquire_consumer(&self) -> Option<Consumer<'_, RelocatablePointer<UnsafeCell<u64>>>> {
        self.state.acquire_consumer()
    }

    /// See [`SafelyOverflowingIndexQueue::is_empty()`]
    pub fn is_empty(&self) -> bool {
        self.state.is_empty()
    }

    /// See [`SafelyOverflowingIndexQueue::len()`]
    pub fn len(&self) -> usize {
        self.state.len()
    }

    /// See [`SafelyOverflowingIndexQueue::push()`]
    ///
    /// # Safety
    ///
    /// * It must be ensured that no other thread/process calls this method concurrently
    ///
    pub unsafe fn push(&self, value: u64) -> Option<u64> {
        unsafe { self.state.push(value) }
    }

    /// See [`SafelyOverflowingIndexQueue::pop()`]
    ///
    /// # Safety
    ///
    /// * It must be ensured that no other thread/process calls this method concurrently
    ///
    pub unsafe fn pop(&self) -> Option<u64> {
        unsafe { self.state.pop() }
    }

    /// See [`SafelyOverflowingIndexQueue::capacity()`]
    pub const fn capacity(&self) -> usize {
        self.state.capacity()
    }

    /// See [`SafelyOverflowingIndexQueue::is_full()`]
    pub fn is_full(&self) -> bool {
        self.state.is_full()
    }
}
