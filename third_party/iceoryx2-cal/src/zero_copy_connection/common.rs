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

#[doc(hidden)]
pub mod details {
    use alloc::vec;
    use alloc::vec::Vec;
    use core::fmt::Debug;
    use core::marker::PhantomData;
    use core::ptr::NonNull;
    use iceoryx2_bb_concurrency::atomic::Ordering;
    use iceoryx2_bb_concurrency::atomic::{AtomicBool, AtomicU8, AtomicU64, AtomicUsize};
    use iceoryx2_bb_elementary::relocatable_pointer::{Pointer, RelocatablePointer};
    use iceoryx2_bb_concurrency::cell::UnsafeCell;
    use iceoryx2_bb_container::vector::relocatable_vec::*;
    use iceoryx2_bb_elementary_traits::allocator::{Allocate, AllocationError};
    use iceoryx2_bb_elementary_traits::relocatable_container::RelocatableContainer;
    use iceoryx2_bb_lock_free::spsc::{
        index_queue::RelocatableIndexQueue,
        safely_overflowing_index_queue::RelocatableSafelyOverflowingIndexQueue,
    };
    use iceoryx2_bb_memory::bump_allocator::BumpAllocator;
    use iceoryx2_bb_posix::adaptive_wait::AdaptiveWaitBuilder;
    use iceoryx2_bb_posix::clock::Time;
    use iceoryx2_bb_posix::file::AccessMode;
    use iceoryx2_log::{fail, fatal_panic};

    pub use crate::zero_copy_connection::*;

    use crate::dynamic_storage::{
        DynamicStorage, DynamicStorageBuilder, DynamicStorageCreateError, DynamicStorageOpenError,
        DynamicStorageOpenOrCreateError,
    };
    use crate::named_concept::*;
    use crate::shared_memory::SegmentId;

    use self::used_chunk_list::RelocatableUsedChunkList;

    #[derive(Debug, PartialEq, Eq, Copy)]
    pub struct Configuration<Storage: DynamicStorage<SharedManagementData>> {
        dynamic_storage_config: Storage::Configuration,
        _data: PhantomData<Storage>,
    }

    impl<Storage: DynamicStorage<SharedManagementData>> Clone for Configuration<Storage> {
        fn clone(&self) -> Self {
            Self {
                dynamic_storage_config: self.dynamic_storage_config.clone(),
                _data: PhantomData,
            }
        }
    }

    impl<Storage: DynamicStorage<SharedManagementData>> Default for Configuration<Storage> {
        fn default() -> Self {
            Self {
                dynamic_storage_config: Storage::Configuration::default()
                    .path_hint(&Connection::<Storage>::default_path_hint())
                    .prefix(&Connection::<Storage>::default_prefix())
                    .suffix(&Connection::<Storage>::default_suffix()),
                _data: PhantomData,
            }
        }
    }

    impl<Storage: DynamicStorage<SharedManagementData>> NamedConceptConfiguration
        for Configuration<Storage>
    {
        fn prefix(mut self, value: &FileName) -> Self {
            self.dynamic_storage_config = self.dynamic_storage_config.prefix(value);
            self
        }

        fn get_prefix(&self) -> &FileName {
            self.dynamic_storage_config.get_prefix()
        }

        fn suffix(mut self, value: &FileName) -> Self {
            self.dynamic_storage_config = self.dynamic_storage_config.suffix(value);
            self
        }

        fn path_hint(mut self, value: &Path) -> Self {
            self.dynamic_storage_config = self.dynamic_storage_config.path_hint(value);
            self
        }

        fn get_suffix(&self) -> &FileName {
            self.dynamic_storage_config.get_suffix()
        }

        fn get_path_hint(&self) -> &Path {
            self.dynamic_storage_config.get_path_hint()
        }

        fn path_for(&self, value: &FileName) -> FilePath {
            self.dynamic_storage_config.path_for(value)
        }

        fn extract_name_from_file(&self, value: &FileName) -> Option<FileName> {
            self.dynamic_storage_config.extract_name_from_file(value)
        }
    }

    #[derive(Debug, Clone, Copy, PartialEq, Eq)]
    #[repr(u8)]
    enum State {
        None = 0b00000000,
        Sender = 0b00000001,
        Receiver = 0b00000010,
        MarkedForDestruction = 0b10000000,
    }

    impl State {
        fn value(&self) -> u8 {
            *self as u8
        }
    }

    fn cleanup_shared_memory<Storage: DynamicStorage<SharedManagementData>>(
        storage: &Storage,
        state_to_remove: State,
    ) {
        let mgmt_data = storage.get();
        if mgmt_data.remove_state(state_to_remove) == State::MarkedForDestruction.value() {
            storage.acquire_ownership()
        }
    }

    #[derive(Debug, ZeroCopySend)]
    #[repr(C)]
    struct SegmentDetails {
        used_chunk_list: RelocatableUsedChunkList,
        sample_size: AtomicUsize,
    }

    impl SegmentDetails {
        fn new_uninit(number_of_samples: usize) -> Self {
            Self {
                used_chunk_list: unsafe { RelocatableUsedChunkList::new_uninit(number_of_samples) },
                sample_size: AtomicUsize::new(0),
            }
        }

        const fn const_memory_size(number_of_samples: usize) -> usize {
            RelocatableUsedChunkList::const_memory_size(number_of_samples)
        }

        unsafe fn init<T: Allocate<NonNull<u8>>>(
            &mut self,
            allocator: &T,
        ) -> Result<(), AllocationError> {
            unsafe { self.used_chunk_list.init(allocator) }
        }
    }

    #[derive(Debug, ZeroCopySend)]
    #[repr(C)]
    struct Channel {
        state: AtomicU64,
        completion_queue: RelocatableIndexQueue,
        submission_queue: RelocatableSafelyOverflowingIndexQueue,
    }

    impl Channel {
        fn new(submission_queue_capacity: usize, completion_queue_capacity: usize) -> Self {
            Self {
                submission_queue: unsafe {
                    RelocatableSafelyOverflowingIndexQueue::new_uninit(submission_queue_capacity)
                },
                completion_queue: unsafe {
                    RelocatableIndexQueue::new_uninit(completion_queue_capacity)
                },
                state: AtomicU64::new(CHANNEL_STATE_OPEN.0),
            }
        }

        const fn const_memory_size(
            submission_queue_capacity: usize,
            completion_queue_capacity: usize,
        ) -> usize {
            RelocatableIndexQueue::const_memory_size(completion_queue_capacity)
                + RelocatableSafelyOverflowingIndexQueue::const_memory_size(
                    submission_queue_capacity,
                )
        }

        fn init(&mut self, allocator: &mut BumpAllocator) {
            let msg = "Failed to initialize channel";
            fatal_panic!(from self, when unsafe { self.submission_queue.init(allocator) },
                        "{} since the submission queue allocation failed. - This is an implementation bug!", msg);
            fatal_panic!(from self, when unsafe { self.completion_queue.init(allocator) },
                        "{} since the completion queue allocation failed. - This is an implementation bug!", msg);
        }
    }

    #[derive(Debug, ZeroCopySend)]
    #[repr(C)]
    pub struct SharedManagementData {
        channels: RelocatableVec<Channel>,
        segment_details: RelocatableVec<SegmentDetails>,
        state: AtomicU8,
        max_borrowed_samples: usize,
        number_of_samples_per_segment: usize,
        number_of_segments: u8,
        enable_safe_overflow: bool,
    }

    impl SharedManagementData {
        fn new(
            enable_safe_overflow: bool,
            max_borrowed_samples: usize,
            number_of_samples_per_segment: usize,
            number_of_segments: u8,
            number_of_channels: usize,
        ) -> Self {
            Self {
                channels: unsafe { RelocatableVec::new_uninit(number_of_channels) },
                segment_details: unsafe {
                    RelocatableVec::new_uninit(number_of_segments as usize * number_of_channels)
                },
                enable_safe_overflow,
                max_borrowed_samples,
                number_of_samples_per_segment,
                number_of_segments,
                state: AtomicU8::new(State::None.value()),
            }
        }

        // DEAR PATCH: the sender no longer indexes the shared vector (see `TrustedLayout`).
        #[allow(dead_code)]
        fn get_segment_details(&self, segment_id: usize, channel_id: usize) -> &SegmentDetails {
            let idx = channel_id * self.number_of_segments as usize + segment_id;
            &self.segment_details[idx]
        }

        fn is_connected(&self) -> bool {
            self.state.load(Ordering::Relaxed) == State::Sender.value() | State::Receiver.value()
        }

        fn remove_state(&self, state_to_remove: State) -> u8 {
            let mut current_state = self.state.load(Ordering::Relaxed);
            if current_state == State::MarkedForDestruction.value() {
                return State::MarkedForDestruction.value();
            }

            loop {
                let new_state = if current_state == state_to_remove.value() {
                    State::MarkedForDestruction.value()
                } else {
                    current_state & !state_to_remove.value()
                };

                match self.state.compare_exchange(
                    current_state,
                    new_state,
                    Ordering::Relaxed,
                    Ordering::Relaxed,
                ) {
                    Ok(_) => {
                        current_state = new_state;
                        break;
                    }
                    Err(s) => {
                        current_state = s;
                    }
                }
            }

            current_state
        }

        fn reserve_port(&self, new_state: u8, msg: &str) -> Result<(), ZeroCopyCreationError> {
            let mut current_state = self.state.load(Ordering::Relaxed);

            loop {
                if current_state & new_state != 0 {
                    fail!(from self, with ZeroCopyCreationError::AnotherInstanceIsAlreadyConnected,
                    "{} since an instance is already connected.", msg);
                } else if current_state & State::MarkedForDestruction.value() != 0 {
                    fail!(from self, with ZeroCopyCreationError::IsBeingCleanedUp,
                    "{} since the connection is currently being cleaned up.", msg);
                }

                match self.state.compare_exchange(
                    current_state,
                    current_state | new_state,
                    Ordering::Relaxed,
                    Ordering::Relaxed,
                ) {
                    Ok(_) => break,
                    Err(v) => {
                        current_state = v;
                    }
                }
            }

            Ok(())
        }

        const fn const_memory_size(
            submission_queue_capacity: usize,
            completion_queue_capacity: usize,
            number_of_samples: usize,
            number_of_segments: u8,
            number_of_channels: usize,
        ) -> usize {
            let number_of_segments = number_of_segments as usize;
            number_of_channels
                * Channel::const_memory_size(submission_queue_capacity, completion_queue_capacity)
                + RelocatableVec::<Channel>::const_memory_size(number_of_channels)
                + SegmentDetails::const_memory_size(number_of_samples)
                    * number_of_segments
                    * number_of_channels
                + RelocatableVec::<SegmentDetails>::const_memory_size(
                    number_of_segments * number_of_channels,
                )
        }

        unsafe fn init(
            &mut self,
            allocator: &mut BumpAllocator,
            submission_queue_capacity: usize,
            completion_queue_capacity: usize,
        ) {
            let msg = "Failed to initialize SharedManagementData";
            // initialize channels
            fatal_panic!(from self, when unsafe {self.channels.init(allocator)},
                "{} since the channels vector allocation failed. - This is an implementation bug!", msg);
            for n in 0..self.channels.capacity() {
                unsafe {
                    self.channels.push_unchecked(Channel::new(
                        submission_queue_capacity,
                        completion_queue_capacity,
                    ))
                };
                self.channels[n].init(allocator);
            }

            // initialize segment details
            fatal_panic!(from self, when unsafe { self.segment_details.init(allocator) },
                        "{} since the used chunk list vector allocation failed. - This is an implementation bug!", msg);

            for n in 0..self.segment_details.capacity() {
                if self
                    .segment_details
                    .push(SegmentDetails::new_uninit(
                        self.number_of_samples_per_segment,
                    ))
                    .is_err()
                {
                    fatal_panic!(from self,
                        "{} since the used chunk list could not be added. - This is an implementation bug!", msg);
                }

                fatal_panic!(from self, when unsafe { self.segment_details[n].init(allocator) },
                    "{} since the used chunk list for segment id {} failed to allocate memory. - This is an implementation bug!",
                    msg, n);
            }
        }
    }


    // DEAR PATCH (issue 34 of DEAR-on-device; third_party/README.md): the sender's private
    // record of the connection's layout and of the chunks it lent. The receiver (another
    // process, possibly hostile or buggy) can write every byte of `SharedManagementData`:
    // the relocatable pointers, lengths and capacities of its vectors and queues, the queue
    // positions, the returned offsets, the used-chunk flags and the sample sizes. Upstream the
    // sender used them as read: 152 random bytes made it abort (debug) or fault (release). The
    // sender now computes where every queue and list must be from the parameters it was built
    // with and the storage's mapping, checks once that the shared record agrees (else the
    // connection is refused), and from then on reads only its own copy: the shared pointers,
    // lengths and capacities are never used again, positions only select a slot modulo the
    // private capacity, and an offset the receiver returns is accepted only if it names a
    // chunk this sender lent on that channel and has not been returned yet. A bad offset marks
    // the connection corrupted: logged once, nothing more is reclaimed from or sent to it, and
    // its lent chunks come back when it is removed.
    #[derive(Debug)]
    struct TrustedQueue {
        data: usize,
        capacity: usize,
    }

    #[derive(Debug)]
    struct TrustedChannel {
        channel: usize,
        submission: TrustedQueue,
        completion: TrustedQueue,
    }

    struct TrustedLayout {
        channels: Vec<TrustedChannel>,
        /// Per (channel, segment): the `SegmentDetails` and its used-chunk flags in shared memory
        /// (written only, to keep the shared record as upstream keeps it).
        segment_details: Vec<(usize, usize)>,
        number_of_segments: usize,
        samples_per_segment: usize,
        max_borrowed_samples: usize,
        enable_safe_overflow: bool,
        /// Per (channel, segment): the sample size this sender last sent with.
        sample_size: Vec<AtomicUsize>,
        /// Per (channel, segment, chunk index): lent to the receiver and not yet returned.
        lent: Vec<AtomicBool>,
        corrupted: AtomicBool,
    }

    impl Debug for TrustedLayout {
        fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
            write!(
                f,
                "TrustedLayout {{ channels: {}, segments: {}, samples_per_segment: {}, corrupted: {} }}",
                self.channels.len(),
                self.number_of_segments,
                self.samples_per_segment,
                self.corrupted.load(Ordering::Relaxed)
            )
        }
    }

    fn dear_align(address: usize, align: usize) -> Option<usize> {
        address.checked_add(align - 1).map(|a| a & !(align - 1))
    }

    /// Replays the initializer's bump allocation (`SharedManagementData::init`).
    struct DearBump {
        next: usize,
    }

    impl DearBump {
        fn take(&mut self, size: usize, align: usize) -> Option<usize> {
            let at = dear_align(self.next, align)?;
            self.next = at.checked_add(size)?;
            Some(at)
        }
    }

    /// The vector header `RelocatableVec<T>` is `#[repr(C)] { data_ptr: RelocatablePointer,
    /// capacity: u64, len: u64 }`: its data address, capacity and length, read without
    /// dereferencing anything they say.
    fn dear_vec_header<T>(vec: &RelocatableVec<T>) -> (usize, u64, u64) {
        let base = vec as *const RelocatableVec<T>;
        let ptr = base as *const RelocatablePointer<u8>;
        let words = base as *const u64;
        // SAFETY: the header is at least three words (asserted at compile time below) and
        // every bit pattern is a valid u64 / distance.
        unsafe {
            (
                (*ptr).as_ptr() as usize,
                core::ptr::read_volatile(words.add(1)),
                core::ptr::read_volatile(words.add(2)),
            )
        }
    }

    const _: () = assert!(core::mem::size_of::<RelocatableVec<Channel>>() == 24);
    const _: () = assert!(core::mem::size_of::<RelocatablePointer<u8>>() == 8);

    impl TrustedLayout {
        /// The layout a sender built with `builder`'s parameters expects in `storage`, checked
        /// against what the shared record says; `Err` names the first difference.
        fn new<Storage: DynamicStorage<SharedManagementData>>(
            storage: &Storage,
            builder: &Builder<Storage>,
        ) -> Result<Self, &'static str> {
            let mgmt = storage.get();
            let number_of_channels = builder.number_of_channels;
            let number_of_segments = builder.number_of_segments as usize;
            let samples = builder.number_of_samples_per_segment;
            let sq_capacity = builder.submission_queue_size();
            let cq_capacity = builder.completion_queue_size();
            if number_of_channels == 0 || number_of_segments == 0 || samples == 0 || cq_capacity == 0 {
                return Err("the sender's own parameters are empty");
            }
            let (channels_data, channels_capacity, channels_len) = dear_vec_header(&mgmt.channels);
            let (range_start, range_end) = match storage.dear_supplementary_range() {
                Some((start, len)) => (start, start.checked_add(len).ok_or("mapping wraps")?),
                // A storage that cannot say (process-local): nobody else writes it.
                None => (channels_data, usize::MAX),
            };
            let mut bump = DearBump { next: range_start };
            let channel_size = core::mem::size_of::<Channel>();
            let channels_at = bump
                .take(channel_size.checked_mul(number_of_channels).ok_or("size overflows")?, core::mem::align_of::<Channel>())
                .ok_or("size overflows")?;
            if channels_data != channels_at
                || channels_capacity != number_of_channels as u64
                || channels_len != number_of_channels as u64
            {
                return Err("the channel vector's header was changed");
            }
            let mut channels = Vec::with_capacity(number_of_channels);
            for n in 0..number_of_channels {
                let submission = bump
                    .take(core::mem::size_of::<u64>() * (sq_capacity + 1), core::mem::align_of::<u64>())
                    .ok_or("size overflows")?;
                let completion = bump
                    .take(core::mem::size_of::<u64>() * cq_capacity, core::mem::align_of::<u64>())
                    .ok_or("size overflows")?;
                channels.push(TrustedChannel {
                    channel: channels_at + n * channel_size,
                    submission: TrustedQueue { data: submission, capacity: sq_capacity },
                    completion: TrustedQueue { data: completion, capacity: cq_capacity },
                });
            }
            let number_of_details = number_of_segments * number_of_channels;
            let details_size = core::mem::size_of::<SegmentDetails>();
            let details_at = bump
                .take(details_size.checked_mul(number_of_details).ok_or("size overflows")?, core::mem::align_of::<SegmentDetails>())
                .ok_or("size overflows")?;
            let mut segment_details = Vec::with_capacity(number_of_details);
            for n in 0..number_of_details {
                let flags = bump
                    .take(core::mem::size_of::<AtomicBool>() * samples, core::mem::align_of::<AtomicBool>())
                    .ok_or("size overflows")?;
                segment_details.push((details_at + n * details_size, flags));
            }
            if bump.next > range_end {
                return Err("the mapping is too short for the connection's layout");
            }
            // The layout lies in this process's mapping: the headers can be read.
            let (details_data, details_capacity, details_len) = dear_vec_header(&mgmt.segment_details);
            if details_data != details_at
                || details_capacity != number_of_details as u64
                || details_len != number_of_details as u64
            {
                return Err("the segment vector's header was changed");
            }
            for c in &channels {
                // SAFETY: within the checked range, aligned for `Channel`.
                let channel = unsafe { &*(c.channel as *const Channel) };
                if channel.submission_queue.dear_data_address() != c.submission.data
                    || channel.submission_queue.capacity() != c.submission.capacity
                    || channel.completion_queue.dear_data_address() != c.completion.data
                    || channel.completion_queue.capacity() != c.completion.capacity
                {
                    return Err("a channel's queue header was changed");
                }
            }
            for (details, flags) in &segment_details {
                // SAFETY: within the checked range, aligned for `SegmentDetails`.
                let details = unsafe { &*(*details as *const SegmentDetails) };
                if details.used_chunk_list.dear_data_address() != *flags
                    || details.used_chunk_list.capacity() != samples
                {
                    return Err("a used-chunk list's header was changed");
                }
            }
            // `enable_safe_overflow` is a `bool` another process may have set to any byte.
            // SAFETY: a field of the mapped record, read as the byte it is.
            let overflow_byte = unsafe {
                core::ptr::read_volatile(core::ptr::addr_of!(mgmt.enable_safe_overflow) as *const u8)
            };
            if overflow_byte != builder.enable_safe_overflow as u8
                || mgmt.number_of_segments != builder.number_of_segments
                || mgmt.number_of_samples_per_segment != samples
                || mgmt.max_borrowed_samples != builder.max_borrowed_samples_per_channel
            {
                return Err("the connection's settings differ");
            }
            Ok(Self {
                channels,
                segment_details,
                number_of_segments,
                samples_per_segment: samples,
                max_borrowed_samples: builder.max_borrowed_samples_per_channel,
                enable_safe_overflow: builder.enable_safe_overflow,
                sample_size: (0..number_of_details).map(|_| AtomicUsize::new(0)).collect(),
                lent: (0..number_of_details * samples).map(|_| AtomicBool::new(false)).collect(),
                corrupted: AtomicBool::new(false),
            })
        }

        fn channel(&self, channel_id: ChannelId) -> Option<&TrustedChannel> {
            self.channels.get(channel_id.value())
        }

        fn channel_ref(&self, c: &TrustedChannel) -> &Channel {
            // SAFETY: checked in `new` to lie in the mapping, which lives as long as the sender.
            unsafe { &*(c.channel as *const Channel) }
        }

        /// Sets chunk `index` of (channel, segment) `details` lent or not, privately and in
        /// the shared list (written, never read); returns whether it was lent before.
        fn set_lent(&self, details: usize, index: usize, value: bool) -> bool {
            let (_, flags) = self.segment_details[details];
            // SAFETY: `flags` holds `samples_per_segment` flags in the mapping (checked in
            // `new`); an AtomicBool is a byte, any value of which is valid to overwrite.
            unsafe { (*(flags as *const AtomicBool).add(index)).store(value, Ordering::Relaxed) };
            self.lent[details * self.samples_per_segment + index].swap(value, Ordering::Relaxed)
        }

        /// Takes back an offset the receiver handed over (returned, or overflowed out of its
        /// queue): accepted only when it names a chunk lent on `channel` and not yet returned.
        fn take_back(&self, value: u64, channel: usize) -> Option<PointerOffset> {
            let offset = PointerOffset::from_value(value);
            let segment = offset.segment_id().value() as usize;
            if segment >= self.number_of_segments {
                return None;
            }
            let details = channel * self.number_of_segments + segment;
            let size = self.sample_size[details].load(Ordering::Relaxed);
            if size == 0 || !offset.offset().is_multiple_of(size) {
                return None;
            }
            let index = offset.offset() / size;
            if index >= self.samples_per_segment
                || !self.lent[details * self.samples_per_segment + index].load(Ordering::Relaxed)
            {
                return None;
            }
            self.set_lent(details, index, false);
            Some(offset)
        }

        fn mark_corrupted(&self, name: &FileName, what: &str, value: u64) {
            if !self.corrupted.swap(true, Ordering::Relaxed) {
                iceoryx2_log::error!(
                    "DEAR PATCH: the receiver of zero-copy connection {:?} {} ({:#x}), which no chunk lent to it has; the connection is marked corrupted: nothing more is sent to or reclaimed from it",
                    name, what, value
                );
            }
        }
    }

    #[derive(Debug)]
    pub struct Builder<Storage: DynamicStorage<SharedManagementData>> {
        name: FileName,
        buffer_size: usize,
        enable_safe_overflow: bool,
        max_borrowed_samples_per_channel: usize,
        number_of_samples_per_segment: usize,
        number_of_segments: u8,
        number_of_channels: usize,
        initial_channel_state: ChannelState,
        timeout: Duration,
        config: Configuration<Storage>,
    }

    impl<Storage: DynamicStorage<SharedManagementData>> Builder<Storage> {
        fn submission_queue_size(&self) -> usize {
            self.buffer_size
        }

        fn completion_queue_size(&self) -> usize {
            self.buffer_size + self.max_borrowed_samples_per_channel + 1
        }

        fn create_or_open_shm(
            &self,
            port_to_register: State,
        ) -> Result<(Storage, Option<TrustedLayout>), ZeroCopyCreationError> {
            // DEAR PATCH: a receiver's number of chunks comes from the sender's entry in the
            // service's shared record (`PublisherDetails`, which any participant can write): a
            // size that cannot be a connection's is refused before the arithmetic below
            // overflows (a panic in debug builds).
            const DEAR_LIMIT: usize = 1 << 24;
            if self.number_of_samples_per_segment > DEAR_LIMIT
                || self.buffer_size > DEAR_LIMIT
                || self.max_borrowed_samples_per_channel > DEAR_LIMIT
                || self.number_of_channels > DEAR_LIMIT
            {
                fail!(from self, with ZeroCopyCreationError::ConnectionMaybeCorrupted,
                    "Failed to acquire underlying shared memory since its parameters are out of range (number of samples {}, buffer size {}, max borrowed samples {}, channels {}): read from a corrupted record (DEAR PATCH).",
                    self.number_of_samples_per_segment, self.buffer_size, self.max_borrowed_samples_per_channel, self.number_of_channels);
            }
            let supplementary_size = SharedManagementData::const_memory_size(
                self.submission_queue_size(),
                self.completion_queue_size(),
                self.number_of_samples_per_segment,
                self.number_of_segments,
                self.number_of_channels,
            );

            let msg = "Failed to acquire underlying shared memory";
            let storage = <<Storage as DynamicStorage<SharedManagementData>>::Builder<'_> as NamedConceptBuilder<
            Storage,
        >>::new(&self.name)
        .config(&self.config.dynamic_storage_config)
        .timeout(self.timeout)
        .supplementary_size(supplementary_size)
        .initializer(|data, allocator| {
            data.write(
                SharedManagementData::new(
                                        self.enable_safe_overflow,
                                        self.max_borrowed_samples_per_channel,
                                        self.number_of_samples_per_segment,
                                        self.number_of_segments,
                                        self.number_of_channels
                                    )
            );
            let data = unsafe{ data.assume_init_mut() };
            unsafe { data.init(allocator, self.submission_queue_size(), self.completion_queue_size())};
            for channel in data.channels.iter() {
                channel.state.store(self.initial_channel_state.0, Ordering::Relaxed);
            }

            true
        })
        .open_or_create();

            let storage = match storage {
                Ok(storage) => storage,
                Err(DynamicStorageOpenOrCreateError::DynamicStorageCreateError(
                    DynamicStorageCreateError::InsufficientPermissions,
                )) => {
                    fail!(from self, with ZeroCopyCreationError::InsufficientPermissions,
                    "{} due to insufficient permissions to create underlying dynamic storage.", msg);
                }
                Err(DynamicStorageOpenOrCreateError::DynamicStorageOpenError(
                    DynamicStorageOpenError::VersionMismatch,
                )) => {
                    fail!(from self, with ZeroCopyCreationError::VersionMismatch,
                    "{} since the version of the connection does not match.", msg);
                }
                Err(DynamicStorageOpenOrCreateError::DynamicStorageOpenError(
                    DynamicStorageOpenError::InitializationNotYetFinalized,
                )) => {
                    fail!(from self, with ZeroCopyCreationError::InitializationNotYetFinalized,
                    "{} since the initialization of the zero copy connection is not finalized.", msg);
                }
                Err(e) => {
                    fail!(from self, with ZeroCopyCreationError::InternalError,
                    "{} due to an internal failure ({:?}).", msg, e);
                }
            };

            storage.get().reserve_port(port_to_register.value(), msg)?;

            // DEAR PATCH: a sender, and a receiver too, checks the whole shared layout against
            // the one it computes and keeps its own copy (`TrustedLayout`); the upstream checks
            // below index the shared vectors as they say, which a corrupted record turns into
            // an abort. (A connection whose settings differ from this port's is refused here
            // as `ConnectionMaybeCorrupted` rather than by the specific upstream error.)
            let trusted = if matches!(port_to_register, State::Sender | State::Receiver) {
                match TrustedLayout::new(&storage, self) {
                    Ok(trusted) => Some(trusted),
                    Err(why) => {
                        cleanup_shared_memory(&storage, port_to_register);
                        fail!(from self, with ZeroCopyCreationError::ConnectionMaybeCorrupted,
                            "{} since its shared record is not the layout this {} expects: {} (DEAR PATCH).",
                            msg, if matches!(port_to_register, State::Sender) { "sender" } else { "receiver" }, why);
                    }
                }
            } else {
                None
            };

            if storage.has_ownership() {
                storage.release_ownership();
            } else if trusted.is_none() {
                let msg = "Failed to open existing connection";

                if storage.get().channels[0].submission_queue.capacity()
                    != self.submission_queue_size()
                {
                    cleanup_shared_memory(&storage, port_to_register);
                    fail!(from self, with ZeroCopyCreationError::IncompatibleBufferSize,
                        "{} since the connection has a buffer size of {} but a buffer size of {} is required.",
                        msg, storage.get().channels[0].submission_queue.capacity(), self.submission_queue_size());
                }

                if storage.get().channels[0].completion_queue.capacity()
                    != self.completion_queue_size()
                {
                    cleanup_shared_memory(&storage, port_to_register);
                    fail!(from self, with ZeroCopyCreationError::IncompatibleMaxBorrowedSamplesPerChannelSetting,
                        "{} since the max borrowed sample per channel setting is set to {} but a value of {} is required.",
                        msg, storage.get().channels[0].completion_queue.capacity() - storage.get().channels[0].submission_queue.capacity(), self.max_borrowed_samples_per_channel);
                }

                if storage.get().enable_safe_overflow != self.enable_safe_overflow {
                    cleanup_shared_memory(&storage, port_to_register);
                    fail!(from self, with ZeroCopyCreationError::IncompatibleOverflowSetting,
                        "{} since the safe overflow is set to {} but should be set to {}.",
                        msg, storage.get().enable_safe_overflow, self.enable_safe_overflow);
                }

                if storage.get().number_of_samples_per_segment != self.number_of_samples_per_segment
                {
                    cleanup_shared_memory(&storage, port_to_register);
                    fail!(from self, with ZeroCopyCreationError::IncompatibleNumberOfSamples,
                        "{} since the requested number of samples is set to {} but should be set to {}.",
                        msg, self.number_of_samples_per_segment, storage.get().number_of_samples_per_segment);
                }

                if storage.get().number_of_segments != self.number_of_segments {
                    cleanup_shared_memory(&storage, port_to_register);
                    fail!(from self, with ZeroCopyCreationError::IncompatibleNumberOfSegments,
                        "{} since the requested number of segments is set to {} but should be set to {}.",
                        msg, self.number_of_segments, storage.get().number_of_segments);
                }

                if storage.get().channels.capacity() != self.number_of_channels {
                    cleanup_shared_memory(&storage, port_to_register);
                    fail!(from self, with ZeroCopyCreationError::IncompatibleNumberOfChannels,
                        "{} since the requested number of channels is set to {} but should be set to {}.",
                        msg, self.number_of_channels, storage.get().channels.capacity());
                }
            }

            Ok((storage, trusted))
        }
    }

    impl<Storage: DynamicStorage<SharedManagementData>> NamedConceptBuilder<Connection<Storage>>
        for Builder<Storage>
    {
        fn new(name: &FileName) -> Self {
            Self {
                name: *name,
                buffer_size: DEFAULT_BUFFER_SIZE,
                enable_safe_overflow: DEFAULT_ENABLE_SAFE_OVERFLOW,
                max_borrowed_samples_per_channel: DEFAULT_MAX_BORROWED_SAMPLES_PER_CHANNEL,
                number_of_samples_per_segment: DEFAULT_NUMBER_OF_SAMPLES_PER_SEGMENT,
                number_of_segments: DEFAULT_MAX_SUPPORTED_SHARED_MEMORY_SEGMENTS,
                number_of_channels: DEFAULT_NUMBER_OF_CHANNELS,
                config: Configuration::default(),
                initial_channel_state: CHANNEL_STATE_OPEN,
                timeout: Duration::ZERO,
            }
        }

        fn config(mut self, config: &Configuration<Storage>) -> Self {
            self.config = config.clone();
            self
        }
    }

    impl<Storage: DynamicStorage<SharedManagementData>>
        ZeroCopyConnectionBuilder<Connection<Storage>> for Builder<Storage>
    {
        fn max_supported_shared_memory_segments(mut self, value: u8) -> Self {
            self.number_of_segments = value.clamp(1, u8::MAX);
            self
        }

        fn initial_channel_state(mut self, value: ChannelState) -> Self {
            self.initial_channel_state = value;
            self
        }

        fn buffer_size(mut self, value: usize) -> Self {
            self.buffer_size = value.clamp(1, usize::MAX);
            self
        }

        fn timeout(mut self, value: Duration) -> Self {
            self.timeout = value;
            self
        }

        fn enable_safe_overflow(mut self, value: bool) -> Self {
            self.enable_safe_overflow = value;
            self
        }

        fn number_of_chunks_per_segment(mut self, value: usize) -> Self {
            self.number_of_samples_per_segment = value.clamp(1, usize::MAX);
            self
        }

        fn receiver_max_borrowed_chunks_per_channel(mut self, value: usize) -> Self {
            self.max_borrowed_samples_per_channel = value.clamp(1, usize::MAX);
            self
        }

        fn number_of_channels(mut self, value: usize) -> Self {
            self.number_of_channels = value.clamp(1, usize::MAX);
            self
        }

        fn create_sender(
            self,
        ) -> Result<<Connection<Storage> as ZeroCopyConnection>::Sender, ZeroCopyCreationError>
        {
            let msg = "Unable to create sender";
            let (storage, trusted) = fail!(from self, when self.create_or_open_shm(State::Sender),
            "{} since the corresponding connection could not be created or opened", msg);
            let Some(trusted) = trusted else {
                fatal_panic!(from self, "This should never happen! A sender has a trusted layout.");
            };

            Ok(Sender {
                storage,
                name: self.name,
                trusted,
            })
        }

        fn create_receiver(
            self,
        ) -> Result<<Connection<Storage> as ZeroCopyConnection>::Receiver, ZeroCopyCreationError>
        {
            let msg = "Unable to create receiver";
            let (storage, trusted) = fail!(from self, when self.create_or_open_shm(State::Receiver),
            "{} since the corresponding connection could not be created or opened", msg);
            let Some(trusted) = trusted else {
                fatal_panic!(from self, "This should never happen! A receiver has a trusted layout.");
            };

            Ok(Receiver {
                storage,
                trusted,
                borrow_counter: {
                    let mut borrow_counter = vec![];
                    for _ in 0..self.number_of_channels {
                        borrow_counter.push(UnsafeCell::new(0));
                    }
                    borrow_counter
                },
                name: self.name,
            })
        }
    }

    #[derive(Debug)]
    pub struct Sender<Storage: DynamicStorage<SharedManagementData>> {
        storage: Storage,
        name: FileName,
        // DEAR PATCH: everything the sender reads of the layout comes from here.
        trusted: TrustedLayout,
    }

    impl<Storage: DynamicStorage<SharedManagementData>> Abandonable for Sender<Storage> {
        unsafe fn abandon_in_place(mut this: NonNull<Self>) {
            let this = unsafe { this.as_mut() };
            unsafe { Storage::abandon_in_place(NonNull::from_mut(&mut this.storage)) };
        }
    }

    impl<Storage: DynamicStorage<SharedManagementData>> Drop for Sender<Storage> {
        fn drop(&mut self) {
            cleanup_shared_memory(&self.storage, State::Sender);
        }
    }

    impl<Storage: DynamicStorage<SharedManagementData>> NamedConcept for Sender<Storage> {
        fn name(&self) -> &FileName {
            &self.name
        }
    }

    impl<Storage: DynamicStorage<SharedManagementData>> ZeroCopyPortDetails for Sender<Storage> {
        // DEAR PATCH: from the sender's private layout, not the shared record.
        fn buffer_size(&self) -> usize {
            self.trusted.channels[0].submission.capacity
        }

        fn max_supported_shared_memory_segments(&self) -> u8 {
            self.trusted.number_of_segments as u8
        }

        fn max_borrowed_chunks(&self) -> usize {
            self.trusted.max_borrowed_samples
        }

        fn has_enabled_safe_overflow(&self) -> bool {
            self.trusted.enable_safe_overflow
        }

        fn is_connected(&self) -> bool {
            self.storage.get().is_connected()
        }

        fn number_of_channels(&self) -> usize {
            self.trusted.channels.len()
        }

        fn __internal_get_channel_state(&self, channel_id: ChannelId) -> &AtomicU64 {
            debug_assert!(channel_id.value() < self.trusted.channels.len());
            let c = &self.trusted.channels[channel_id.value()];
            &self.trusted.channel_ref(c).state
        }
    }

    // DEAR PATCH: every method reads the layout from `self.trusted` (see `TrustedLayout`)
    // and validates what the receiver wrote (overflowed and returned offsets) before use.
    impl<Storage: DynamicStorage<SharedManagementData>> ZeroCopySender for Sender<Storage> {
        fn try_send(
            &self,
            ptr: PointerOffset,
            sample_size: usize,
            channel_id: ChannelId,
        ) -> Result<Option<PointerOffset>, ZeroCopySendError> {
            let msg = "Unable to send sample";
            let trusted = &self.trusted;
            if trusted.corrupted.load(Ordering::Relaxed) {
                fail!(from self, with ZeroCopySendError::ConnectionCorrupted,
                    "{} since the receiver corrupted the connection.", msg);
            }
            let Some(channel) = trusted.channel(channel_id) else {
                fail!(from self, with ZeroCopySendError::InternalError,
                    "{} since the channel {:?} does not exist.", msg, channel_id);
            };
            let shared = trusted.channel_ref(channel);

            if !trusted.enable_safe_overflow
                && shared.submission_queue.dear_is_full(channel.submission.capacity)
            {
                fail!(from self, with ZeroCopySendError::ReceiveBufferFull,
                             "{} since the receive buffer is full.", msg);
            }

            let segment_id = ptr.segment_id().value() as usize;
            if segment_id >= trusted.number_of_segments
                || sample_size == 0
                || !ptr.offset().is_multiple_of(sample_size)
                || ptr.offset() / sample_size >= trusted.samples_per_segment
            {
                fail!(from self, with ZeroCopySendError::InternalError,
                    "{} since the offset {:?} with sample size {} is outside the segment.", msg, ptr, sample_size);
            }
            let details = channel_id.value() * trusted.number_of_segments + segment_id;
            trusted.sample_size[details].store(sample_size, Ordering::Relaxed);
            // SAFETY: checked in `TrustedLayout::new`; kept for the shared record only.
            unsafe { &*(trusted.segment_details[details].0 as *const SegmentDetails) }
                .sample_size
                .store(sample_size, Ordering::Relaxed);
            let index = ptr.offset() / sample_size;

            let was_lent = trusted.set_lent(details, index, true);
            debug_assert!(!was_lent);

            // SAFETY: the slots' address and capacity were computed and checked privately.
            match unsafe {
                shared.submission_queue.dear_push(
                    channel.submission.data as *const UnsafeCell<u64>,
                    channel.submission.capacity,
                    ptr.as_value(),
                )
            } {
                Some(v) => match trusted.take_back(v, channel_id.value()) {
                    Some(pointer_offset) => Ok(Some(pointer_offset)),
                    None => {
                        // The sample just queued is not counted as delivered by the caller
                        // (this is an error): it must not be given back as lent either when
                        // the connection is removed (`acquire_used_offsets`), or its chunk's
                        // reference count would drop below the deliveries it counts.
                        trusted.set_lent(details, index, false);
                        trusted.mark_corrupted(&self.name, "overwrote its receive queue with an offset", v);
                        fail!(from self, with ZeroCopySendError::ConnectionCorrupted,
                            "{} since the invalid offset {:#x} was returned on overflow.", msg, v);
                    }
                },
                None => Ok(None),
            }
        }

        fn blocking_send<F: BackpressureToReceiverFn>(
            &self,
            ptr: PointerOffset,
            sample_size: usize,
            channel_id: ChannelId,
            backpressure_to_receiver_handler: F,
            backpressure_action_for_strategy: BackpressureToReceiverAction,
        ) -> Result<Option<PointerOffset>, ZeroCopySendError> {
            let msg = "Unable to blocking send the offset";
            let trusted = &self.trusted;
            let Some(channel) = trusted.channel(channel_id) else {
                fail!(from self, with ZeroCopySendError::InternalError,
                    "{} since the channel {:?} does not exist.", msg, channel_id);
            };
            let shared = trusted.channel_ref(channel);
            let capacity = channel.submission.capacity;

            let mgmt = self.storage.get();
            if !trusted.enable_safe_overflow
                && !trusted.corrupted.load(Ordering::Relaxed)
                && shared.submission_queue.dear_is_full(capacity)
            {
                let mut is_connected = false;
                let mut has_valid_channel_state = false;
                let mut do_fail = false;
                let mut retry_until_delivered = false;
                let mut retry_counter = 0;
                let start = Time::now().unwrap();

                const WAIT_CONTINUE: bool = true;
                const WAIT_ABORT: bool = false;

                if let Err(e) = AdaptiveWaitBuilder::new().create().unwrap().wait_while(|| {
                    is_connected = mgmt.is_connected();
                    has_valid_channel_state =
                        shared.state.load(Ordering::Relaxed) != CHANNEL_STATE_CLOSED.0;
                    if is_connected
                        && has_valid_channel_state
                        && shared.submission_queue.dear_is_full(capacity)
                    {
                        if retry_until_delivered {
                            WAIT_CONTINUE
                        } else {
                            let wait_action = match backpressure_to_receiver_handler(
                                retry_counter,
                                start.elapsed().unwrap_or(Duration::MAX),
                            ) {
                                BackpressureToReceiverAction::FollowBackpressureyStrategy => {
                                    match backpressure_action_for_strategy {
                                        BackpressureToReceiverAction::Retry => {
                                            retry_until_delivered = true;
                                            WAIT_CONTINUE
                                        }
                                        _ => WAIT_ABORT,
                                    }
                                }
                                BackpressureToReceiverAction::Retry => WAIT_CONTINUE,
                                BackpressureToReceiverAction::DiscardPointerOffset => WAIT_ABORT,
                                BackpressureToReceiverAction::DiscardPointerOffsetAndFail => {
                                    do_fail = true;
                                    WAIT_ABORT
                                }
                            };
                            retry_counter += 1;
                            wait_action
                        }
                    } else {
                        WAIT_ABORT
                    }
                }) {
                    fail!(from self, with ZeroCopySendError::InternalError,
                        "{msg} {ptr:?} via channel {channel_id:?} since the adaptive wait failed. [{e:?}]");
                }

                if !is_connected {
                    fail!(from self, with ZeroCopySendError::NoConnectedReceiverAndBufferIsFull,
                        "{msg} {ptr:?} via channel {channel_id:?} since there is no connected receiver and the buffer is full. To prevent a deadlock on sender side the operation is aborted.");
                }

                if !has_valid_channel_state {
                    fail!(from self, with ZeroCopySendError::ChannelIsClosed,
                        "{msg} {ptr:?} via channel {channel_id:?} since the channel is closed.");
                }

                if do_fail {
                    fail!(from self, with ZeroCopySendError::UnableToDeliver,
                          "{msg} {ptr:?} via channel {channel_id:?} since the receive buffer is full.");
                }
            }
            self.try_send(ptr, sample_size, channel_id)
        }

        fn reclaim(
            &self,
            channel_id: ChannelId,
        ) -> Result<Option<PointerOffset>, ZeroCopyReclaimError> {
            let msg = "Unable to reclaim sample";
            let trusted = &self.trusted;
            // A corrupted connection gives nothing back (its chunks come back when it is
            // removed): callers loop until `None`, and its positions may say "2^64 entries".
            if trusted.corrupted.load(Ordering::Relaxed) {
                return Ok(None);
            }
            let Some(channel) = trusted.channel(channel_id) else {
                return Ok(None);
            };
            let shared = trusted.channel_ref(channel);
            // SAFETY: the slots' address and capacity were computed and checked privately.
            match unsafe {
                shared.completion_queue.dear_pop(
                    channel.completion.data as *const UnsafeCell<u64>,
                    channel.completion.capacity,
                )
            } {
                None => Ok(None),
                Some(v) => match trusted.take_back(v, channel_id.value()) {
                    Some(pointer_offset) => Ok(Some(pointer_offset)),
                    None => {
                        trusted.mark_corrupted(&self.name, "returned an offset", v);
                        fail!(from self, with ZeroCopyReclaimError::ReceiverReturnedCorruptedPointerOffset,
                            "{} since the receiver returned a corrupted offset {:#x}.", msg, v);
                    }
                },
            }
        }

        unsafe fn acquire_used_offsets<F: FnMut(PointerOffset)>(&self, mut callback: F) {
            let trusted = &self.trusted;
            for details in 0..trusted.segment_details.len() {
                let size = trusted.sample_size[details].load(Ordering::Relaxed);
                for index in 0..trusted.samples_per_segment {
                    if trusted.lent[details * trusted.samples_per_segment + index]
                        .load(Ordering::Relaxed)
                    {
                        trusted.set_lent(details, index, false);
                        callback(PointerOffset::from_offset_and_segment_id(
                            index * size,
                            self.segment_id_from_index(details),
                        ))
                    }
                }
            }
        }
    }

    impl<Storage: DynamicStorage<SharedManagementData>> Sender<Storage> {
        fn segment_id_from_index(&self, index: usize) -> SegmentId {
            // DEAR PATCH: the private count (the shared one may be 0).
            let number_of_segments = self.trusted.number_of_segments;
            // the segment details contain an entry for every channel in every segment.
            // so it is in memory a vector of vector where the first index is the
            // channel id and the second is the segment id. this vector is, to make the
            // relocatable construction easier, mapped to a one dimension vector with the
            // same memory layout.
            //
            // example for 3 segments and 4 channels
            //
            // index       segment id      channel id
            // 0           0               0
            // 1           1               0
            // 2           2               0
            // 3           0               1
            // 4           1               1
            // 5           2               1
            // 6           0               2
            // 7           1               2
            // 8           2               2
            // 9           0               3
            // 10          1               3
            // 11          2               3
            //
            // to map an index to a segment id, we need to subtract from index the
            // rounded down value of index which is rounded down to the greatest multiple
            // of number_of_segments.
            SegmentId::new((index - (index / number_of_segments) * number_of_segments) as u8)
        }
    }

    #[derive(Debug)]
    pub struct Receiver<Storage: DynamicStorage<SharedManagementData>> {
        storage: Storage,
        borrow_counter: Vec<UnsafeCell<usize>>,
        name: FileName,
        // DEAR PATCH: everything the receiver reads of the layout comes from here (the sender,
        // or any process that can write the record, may have overwritten the shared one).
        trusted: TrustedLayout,
    }

    impl<Storage: DynamicStorage<SharedManagementData>> Abandonable for Receiver<Storage> {
        unsafe fn abandon_in_place(mut this: NonNull<Self>) {
            let this = unsafe { this.as_mut() };
            unsafe { Storage::abandon_in_place(NonNull::from_mut(&mut this.storage)) };
        }
    }

    impl<Storage: DynamicStorage<SharedManagementData>> Drop for Receiver<Storage> {
        fn drop(&mut self) {
            cleanup_shared_memory(&self.storage, State::Receiver);
        }
    }

    impl<Storage: DynamicStorage<SharedManagementData>> Receiver<Storage> {
        #[allow(clippy::mut_from_ref)]
        // convenience to access internal mutable object
        fn borrow_counter(&self, channel_id: ChannelId) -> &mut usize {
            #[deny(clippy::mut_from_ref)]
            unsafe {
                &mut *self.borrow_counter[channel_id.value()].get()
            }
        }

    }

    impl<Storage: DynamicStorage<SharedManagementData>> NamedConcept for Receiver<Storage> {
        fn name(&self) -> &FileName {
            &self.name
        }
    }

    // DEAR PATCH: from the receiver's private layout, not the shared record.
    impl<Storage: DynamicStorage<SharedManagementData>> ZeroCopyPortDetails for Receiver<Storage> {
        fn buffer_size(&self) -> usize {
            self.trusted.channels[0].submission.capacity
        }

        fn max_supported_shared_memory_segments(&self) -> u8 {
            self.trusted.number_of_segments as u8
        }

        fn max_borrowed_chunks(&self) -> usize {
            self.trusted.max_borrowed_samples
        }

        fn has_enabled_safe_overflow(&self) -> bool {
            self.trusted.enable_safe_overflow
        }

        fn is_connected(&self) -> bool {
            self.storage.get().is_connected()
        }

        fn number_of_channels(&self) -> usize {
            self.trusted.channels.len()
        }

        fn __internal_get_channel_state(&self, channel_id: ChannelId) -> &AtomicU64 {
            debug_assert!(channel_id.value() < self.trusted.channels.len());
            let c = &self.trusted.channels[channel_id.value()];
            &self.trusted.channel_ref(c).state
        }
    }

    // DEAR PATCH: every method reads the layout from `self.trusted` (see `TrustedLayout`); the
    // queue positions only select a slot modulo the private capacity, and an offset read from
    // the submission queue is accepted only if it names a segment of the connection (the data
    // segment's bounds are checked by the caller, which maps it). A corrupted connection has
    // "data" (so that the caller reaches `receive`) and `receive` fails with
    // `ConnectionCorrupted`.
    impl<Storage: DynamicStorage<SharedManagementData>> ZeroCopyReceiver for Receiver<Storage> {
        fn has_data(&self, channel_id: ChannelId) -> bool {
            if self.trusted.corrupted.load(Ordering::Relaxed) {
                return true;
            }
            let Some(channel) = self.trusted.channel(channel_id) else {
                return false;
            };
            !self.trusted.channel_ref(channel).submission_queue.dear_is_empty()
        }

        fn receive(
            &self,
            channel_id: ChannelId,
        ) -> Result<Option<PointerOffset>, ZeroCopyReceiveError> {
            let trusted = &self.trusted;
            if trusted.corrupted.load(Ordering::Relaxed) {
                fail!(from self, with ZeroCopyReceiveError::ConnectionCorrupted,
                    "Unable to receive another sample since the connection is corrupted.");
            }
            let Some(channel) = trusted.channel(channel_id) else {
                return Ok(None);
            };

            if *self.borrow_counter(channel_id) >= trusted.max_borrowed_samples {
                fail!(from self, with ZeroCopyReceiveError::ReceiveWouldExceedMaxBorrowValue,
                "Unable to receive another sample since already {} samples were borrowed and this would exceed the max borrow value of {}.",
                    self.borrow_counter(channel_id), self.max_borrowed_chunks());
            }

            let queue = &trusted.channel_ref(channel).submission_queue;
            if !queue.dear_positions_plausible(channel.submission.capacity) {
                self.dear_mark_corrupted("its receive queue's positions were overwritten", 0);
                fail!(from self, with ZeroCopyReceiveError::ConnectionCorrupted,
                    "Unable to receive another sample since the receive queue's positions were overwritten.");
            }
            // SAFETY: the slots' address and capacity were computed and checked privately.
            match unsafe {
                queue.dear_pop(
                    channel.submission.data as *const UnsafeCell<u64>,
                    channel.submission.capacity,
                )
            } {
                None => Ok(None),
                Some(v) => {
                    let offset = PointerOffset::from_value(v);
                    if offset.segment_id().value() as usize >= trusted.number_of_segments {
                        self.dear_mark_corrupted("it delivered an offset of a segment it does not have", v);
                        fail!(from self, with ZeroCopyReceiveError::ConnectionCorrupted,
                            "Unable to receive another sample since the received offset {:#x} names no segment of the connection.", v);
                    }
                    *self.borrow_counter(channel_id) += 1;
                    Ok(Some(offset))
                }
            }
        }

        fn borrow_count(&self, channel_id: ChannelId) -> usize {
            match self.borrow_counter.get(channel_id.value()) {
                Some(_) => *self.borrow_counter(channel_id),
                None => 0,
            }
        }

        fn release(
            &self,
            ptr: PointerOffset,
            channel_id: ChannelId,
        ) -> Result<(), ZeroCopyReleaseError> {
            let trusted = &self.trusted;
            let Some(channel) = trusted.channel(channel_id) else {
                return Ok(());
            };
            let counter = self.borrow_counter(channel_id);
            if trusted.corrupted.load(Ordering::Relaxed) {
                // Nothing goes back through a corrupted connection; the sender takes its
                // chunks back when the connection is removed.
                *counter = counter.saturating_sub(1);
                return Ok(());
            }

            // SAFETY: the slots' address and capacity were computed and checked privately.
            match unsafe {
                trusted.channel_ref(channel).completion_queue.dear_push(
                    channel.completion.data as *const UnsafeCell<u64>,
                    channel.completion.capacity,
                    ptr.as_value(),
                )
            } {
                true => {
                    *counter = counter.saturating_sub(1);
                    Ok(())
                }
                false => {
                    fail!(from self, with ZeroCopyReleaseError::RetrieveBufferFull,
                    "Unable to release pointer since the retrieve buffer is full.");
                }
            }
        }

        /// DEAR PATCH: marks the connection corrupted (logged once, counted in `dear_shared`):
        /// from then on `receive` fails with `ConnectionCorrupted` and nothing is returned to
        /// the sender through it.
        fn dear_mark_corrupted(&self, what: &str, value: u64) {
            if !self.trusted.corrupted.swap(true, Ordering::Relaxed) {
                iceoryx2_bb_lock_free::dear_shared::note_corruption();
                iceoryx2_log::error!(
                    "DEAR PATCH: zero-copy connection {:?}: {} ({:#x}); the connection is marked corrupted: nothing more is received from or returned through it (connect again)",
                    self.name, what, value
                );
            }
        }
    }


    #[derive(Debug)]
    pub struct Connection<Storage: DynamicStorage<SharedManagementData>> {
        _data: PhantomData<Storage>,
    }

    impl<Storage: DynamicStorage<SharedManagementData>> NamedConceptMgmt for Connection<Storage> {
        type Configuration = Configuration<Storage>;

        fn does_exist_cfg(
            name: &FileName,
            cfg: &Self::Configuration,
        ) -> Result<bool, crate::static_storage::file::NamedConceptDoesExistError> {
            Ok(fail!(from "ZeroCopyConnection::does_exist_cfg()",
                    when Storage::does_exist_cfg(name, &cfg.dynamic_storage_config),
                    "Failed to check if ZeroCopyConnection \"{}\" exists.",
                    name))
        }

        fn list_cfg(
            cfg: &Self::Configuration,
        ) -> Result<Vec<FileName>, crate::static_storage::file::NamedConceptListError> {
            Ok(fail!(from "ZeroCopyConnection::list_cfg()",
                    when Storage::list_cfg(&cfg.dynamic_storage_config),
                    "Failed to list all ZeroCopyConnections."))
        }

        unsafe fn remove_cfg(
            name: &FileName,
            cfg: &Self::Configuration,
        ) -> Result<bool, crate::static_storage::file::NamedConceptRemoveError> {
            Ok(fail!(from "ZeroCopyConnection::remove_cfg()",
                    when unsafe {Storage::remove_cfg(name, &cfg.dynamic_storage_config) },
                    "Failed to remove ZeroCopyConnection \"{}\".", name))
        }

        fn remove_path_hint(_value: &Path) -> Result<(), NamedConceptPathHintRemoveError> {
            Ok(())
        }
    }
    /// DEAR PATCH: the channels of a connection opened without its builder's parameters (to
    /// remove a dead port): their address and count as the shared vector header says, used
    /// only if they lie in the storage's mapping, aligned; `None` otherwise.
    fn dear_channels<Storage: DynamicStorage<SharedManagementData>>(
        storage: &Storage,
    ) -> Option<(usize, usize)> {
        let (data, capacity, len) = dear_vec_header(&storage.get().channels);
        let (start, size) = storage.dear_supplementary_range()?;
        let count = usize::try_from(len).ok()?;
        let bytes = count.checked_mul(core::mem::size_of::<Channel>())?;
        let end = data.checked_add(bytes)?;
        (len <= capacity
            && data >= start
            && end <= start.checked_add(size)?
            && data.is_multiple_of(core::mem::align_of::<Channel>()))
        .then_some((data, count))
    }

    impl<Storage: DynamicStorage<SharedManagementData>> Connection<Storage> {
        fn remove_port(
            name: &FileName,
            config: &<Connection<Storage> as NamedConceptMgmt>::Configuration,
            msg: &str,
            port: State,
        ) -> Result<(), ZeroCopyPortRemoveError> {
            let origin = "Connection::open_storage()";
            match <<Storage as DynamicStorage<SharedManagementData>>::Builder<'_> as NamedConceptBuilder<
                    Storage>>::new(name)
                       .config(&config.dynamic_storage_config).open(AccessMode::ReadWrite) {
                           Ok(storage) => {
                               // DEAR PATCH: the channel vector's header is shared (the
                               // other port may have overwritten it): its channels are closed
                               // only if they lie in the mapping, else left as they are.
                               match dear_channels(&storage) {
                                   Some((channels, count)) => {
                                       for n in 0..count {
                                           // SAFETY: checked by `dear_channels`.
                                           let channel = unsafe { &*(channels as *const Channel).add(n) };
                                           channel.state.store(CHANNEL_STATE_CLOSED.0, Ordering::Relaxed);
                                       }
                                   }
                                   None => {
                                       iceoryx2_log::error!(from origin, "DEAR PATCH: the channel vector of zero-copy connection {:?} is corrupted; removing the port without closing its channels", name);
                                   }
                               }
                               cleanup_shared_memory(&storage, port); Ok(())},
                           Err(DynamicStorageOpenError::InitializationNotYetFinalized) => {
                               match unsafe { Storage::remove_cfg(name, &config.dynamic_storage_config) } {
                                   Ok(_) => Ok(()),
                                   Err(NamedConceptRemoveError::InsufficientPermissions) => {
                                       fail!(from origin, with ZeroCopyPortRemoveError::InsufficientPermissions,
                                           "{msg} since the underlying dynamic storage has a different iceoryx2 version.");
                                   }
                                   Err(NamedConceptRemoveError::Interrupt) => {
                                       fail!(from origin, with ZeroCopyPortRemoveError::Interrupt,
                                           "{msg} since an interrupt signal was raised.");
                                   }
                                   Err(NamedConceptRemoveError::InternalError) => {
                                       fail!(from origin, with ZeroCopyPortRemoveError::InternalError,
                                           "{msg} due to an internal error.");
                                   }
                               }
                           }
                           Err(DynamicStorageOpenError::VersionMismatch) => {
                               fail!(from origin, with ZeroCopyPortRemoveError::VersionMismatch,
                                   "{msg} since the underlying dynamic storage has a different iceoryx2 version.");
                           }
                           Err(DynamicStorageOpenError::DoesNotExist) => {
                               fail!(from origin, with ZeroCopyPortRemoveError::DoesNotExist,
                                   "{msg} since the underlying dynamic storage does not exist.");
                           }
                           Err(DynamicStorageOpenError::InternalError) => {
                               fail!(from origin, with ZeroCopyPortRemoveError::InternalError,
                                   "{msg} due to an internal error.");
                           }
                       }
        }
    }

    impl<Storage: DynamicStorage<SharedManagementData>> ZeroCopyConnection for Connection<Storage> {
        type Sender = Sender<Storage>;
        type Builder = Builder<Storage>;
        type Receiver = Receiver<Storage>;

        unsafe fn remove_sender(
            name: &FileName,
            config: &Self::Configuration,
        ) -> Result<(), ZeroCopyPortRemoveError> {
            Self::remove_port(
                name,
                config,
                "Unable to remove forcefully the sender of the Zero Copy Connection",
                State::Sender,
            )
        }

        unsafe fn remove_receiver(
            name: &FileName,
            config: &Self::Configuration,
        ) -> Result<(), ZeroCopyPortRemoveError> {
            Self::remove_port(
                name,
                config,
                "Unable to remove forcefully the receiver of the Zero Copy Connection",
                State::Receiver,
            )
        }

        fn does_support_safe_overflow() -> bool {
            true
        }

        fn has_configurable_buffer_size() -> bool {
            true
        }
    }
}
