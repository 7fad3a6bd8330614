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

/// The dynamic service configuration of an
/// [`MessagingPattern::Event`](crate::service::messaging_pattern::MessagingPattern::Event)
/// based service.
pub mod event;

/// The dynamic service configuration of an
/// [`MessagingPattern::PublishSubscribe`](crate::service::messaging_pattern::MessagingPattern::PublishSubscribe)
/// based service.
pub mod publish_subscribe;

/// The dynamic service configuration of an
/// [`MessagingPattern::RequestResponse`](crate::service::messaging_pattern::MessagingPattern::RequestResponse)
/// based service.
pub mod request_response;

/// The dynamic service configuration of an
/// [`MessagingPattern::Blackboard`](crate::service::messaging_pattern::MessagingPattern::Blackboard)
/// based service.
pub mod blackboard;

use core::fmt::Display;
use iceoryx2_bb_container::queue::RelocatableContainer;
use iceoryx2_bb_derive_macros::ZeroCopySend;
use iceoryx2_bb_elementary::CallbackProgression;
use iceoryx2_bb_elementary_traits::zero_copy_send::ZeroCopySend;
use iceoryx2_bb_lock_free::mpmc::unique_index_set_enums::{ReleaseMode, ReleaseState};
use iceoryx2_bb_memory::bump_allocator::BumpAllocator;
use iceoryx2_cal::bag::{Bag, BagFamily, BagStateFamily};
use iceoryx2_cal::bag::{BagAddFailure, BagRemoveError};
use iceoryx2_log::{fail, fatal_panic};

use crate::identifiers::{UniqueNodeId, UniquePortId};

#[derive(Debug, PartialEq, Eq)]
pub(crate) enum PortCleanupAction {
    RemovePort,
    SkipPort,
}

#[derive(Debug)]
pub(crate) enum RegisterNodeResult {
    MarkedForDestruction,
    ExceedsMaxNumberOfNodes,
}

pub(crate) enum DeregisterNodeState {
    HasOwners,
    NoMoreOwners,
}

#[derive(Debug)]
pub(crate) enum MessagingPatternSettings {
    RequestResponse(request_response::DynamicConfigSettings),
    PublishSubscribe(publish_subscribe::DynamicConfigSettings),
    Event(event::DynamicConfigSettings),
    Blackboard(blackboard::DynamicConfigSettings),
}

#[derive(Debug, ZeroCopySend)]
#[repr(C)]
pub(crate) enum MessagingPattern<B: BagFamily> {
    RequestResponse(request_response::DynamicConfig<B>),
    PublishSubscribe(publish_subscribe::DynamicConfig<B>),
    Event(event::DynamicConfig<B>),
    Blackboard(blackboard::DynamicConfig<B>),
}

impl<B: BagFamily> MessagingPattern<B> {
    pub(crate) fn new(settings: &MessagingPatternSettings) -> Self {
        match settings {
            MessagingPatternSettings::RequestResponse(v) => {
                MessagingPattern::RequestResponse(request_response::DynamicConfig::new(v))
            }
            MessagingPatternSettings::PublishSubscribe(v) => {
                MessagingPattern::PublishSubscribe(publish_subscribe::DynamicConfig::new(v))
            }
            MessagingPatternSettings::Event(v) => {
                MessagingPattern::Event(event::DynamicConfig::new(v))
            }
            MessagingPatternSettings::Blackboard(v) => {
                MessagingPattern::Blackboard(blackboard::DynamicConfig::new(v))
            }
        }
    }
}

#[doc(hidden)]
// DEAR PATCH: `Debug` by hand (below): the derived one read the enum's tag, which lives in
// memory every participant writes.
#[derive(ZeroCopySend)]
#[repr(C)]
pub struct DynamicConfig<B: BagFamily> {
    messaging_pattern: MessagingPattern<B>,
    nodes: B::Bag<UniqueNodeId>,
}

// DEAR PATCH (issue 34 of DEAR-on-device; third_party/README.md): `MessagingPattern` is a
// Rust enum in shared memory, and any participant can overwrite its tag: a flipped bit made
// `publish_subscribe()` take its "never happens" branch and fault while formatting the
// garbage, and a tag outside 0..=3 is undefined behaviour in any `match`. A process knows
// which pattern its service is (the static config, written once by its creator and
// read-only), so the accessors no longer read the tag: they take the variant's payload at
// its fixed offset in the `repr(C)` layout (mirrored by `DearShadow`). Code that must branch
// on the tag reads it as the integer it is (`dear_tag`) and skips values it does not know.
#[allow(dead_code)]
#[repr(C)]
union DearPayload<B: BagFamily> {
    request_response: core::mem::ManuallyDrop<request_response::DynamicConfig<B>>,
    publish_subscribe: core::mem::ManuallyDrop<publish_subscribe::DynamicConfig<B>>,
    event: core::mem::ManuallyDrop<event::DynamicConfig<B>>,
    blackboard: core::mem::ManuallyDrop<blackboard::DynamicConfig<B>>,
}

/// The layout of a `#[repr(C)]` enum with fields: a C `int` tag, then a union of the variants.
#[allow(dead_code)]
#[repr(C)]
struct DearShadow<B: BagFamily> {
    tag: core::ffi::c_int,
    payload: DearPayload<B>,
}

impl<B: BagFamily> core::fmt::Debug for DynamicConfig<B> {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(f, "DynamicConfig {{ messaging_pattern tag: {} }}", self.dear_tag())
    }
}

impl<B: BagFamily> Display for DynamicConfig<B> {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        // DEAR PATCH: the tag as a number (see `DearShadow`).
        write!(
            f,
            "service::DynamicConfig {{ messaging_pattern tag: {} }}",
            self.dear_tag()
        )
    }
}

impl<B: BagFamily> DynamicConfig<B> {
    /// DEAR PATCH: the messaging pattern's tag as stored (0 request-response, 1
    /// publish-subscribe, 2 event, 3 blackboard, anything else: overwritten).
    fn dear_tag(&self) -> core::ffi::c_int {
        const {
            assert!(
                core::mem::size_of::<DearShadow<B>>() == core::mem::size_of::<MessagingPattern<B>>()
                    && core::mem::align_of::<DearShadow<B>>()
                        == core::mem::align_of::<MessagingPattern<B>>()
            )
        };
        // SAFETY: the tag is the first C int of the `repr(C)` enum; any value is a valid int.
        unsafe {
            core::ptr::read_volatile(
                &self.messaging_pattern as *const MessagingPattern<B> as *const core::ffi::c_int,
            )
        }
    }

    /// DEAR PATCH: the variant `V`'s payload, wherever the tag points (see `DearShadow`).
    /// The caller names the variant its service is.
    fn dear_payload<V>(&self) -> &V {
        let at = core::mem::offset_of!(DearShadow<B>, payload);
        // SAFETY: the payload of every variant starts at `at` in the `repr(C)` layout; the
        // caller's service is of that variant (its static config says so), so the memory
        // there was initialised as a `V` by the service's creator.
        unsafe {
            &*((&self.messaging_pattern as *const MessagingPattern<B> as *const u8).add(at)
                as *const V)
        }
    }

    pub(crate) fn new_uninit(
        messaging_pattern: MessagingPattern<B>,
        max_number_of_nodes: usize,
    ) -> Self {
        Self {
            messaging_pattern,
            nodes: unsafe { B::Bag::new_uninit(max_number_of_nodes) },
        }
    }

    pub(crate) fn memory_size(max_number_of_nodes: usize) -> usize {
        B::Bag::<UniqueNodeId>::memory_size(max_number_of_nodes)
    }

    pub(crate) unsafe fn init(&mut self, allocator: &BumpAllocator) {
        unsafe {
            fatal_panic!(from self, when self.nodes.init(allocator),
            "This should never happen! Unable to initialize NodeId container.");
            match &mut self.messaging_pattern {
                MessagingPattern::PublishSubscribe(v) => v.init(allocator),
                MessagingPattern::Event(v) => v.init(allocator),
                MessagingPattern::RequestResponse(v) => v.init(allocator),
                MessagingPattern::Blackboard(v) => v.init(allocator),
            }
        }
    }

    pub(crate) unsafe fn remove_dead_node_id<
        PortCleanup: FnMut(UniquePortId) -> PortCleanupAction,
    >(
        &self,
        node_id: &UniqueNodeId,
        port_cleanup_callback: PortCleanup,
    ) -> DeregisterNodeState {
        unsafe {
            // DEAR PATCH: branch on the tag as an integer; an overwritten one skips the ports'
            // cleanup (the node's entry below is still recovered).
            match self.dear_tag() {
                1 => {
                    self.dear_payload::<publish_subscribe::DynamicConfig<B>>()
                        .remove_dead_node_id(node_id, port_cleanup_callback);
                }
                2 => {
                    self.dear_payload::<event::DynamicConfig<B>>()
                        .remove_dead_node_id(node_id, port_cleanup_callback);
                }
                0 => {
                    self.dear_payload::<request_response::DynamicConfig<B>>()
                        .remove_dead_node_id(node_id, port_cleanup_callback);
                }
                3 => {
                    self.dear_payload::<blackboard::DynamicConfig<B>>()
                        .remove_dead_node_id(node_id, port_cleanup_callback);
                }
                tag => {
                    iceoryx2_log::error!(from self, "DEAR PATCH: the service's messaging pattern tag was overwritten ({tag}); the dead node's ports are not cleaned up");
                }
            };

            match self.nodes.recover(
                node_id.owner_id(),
                |entry_node_id| {
                    // additional comparison, since the node_id.owner_id() might be not enough
                    entry_node_id == *node_id
                },
                ReleaseMode::LockIfLastIndex,
            ) {
                ReleaseState::Locked => DeregisterNodeState::NoMoreOwners,
                ReleaseState::Unlocked => DeregisterNodeState::HasOwners,
            }
        }
    }

    pub(crate) fn register_node_id(
        &self,
        node_id: UniqueNodeId,
    ) -> Result<B::BagHandle, RegisterNodeResult> {
        let msg = "Unable to register NodeId in service";
        match unsafe { self.nodes.add(node_id, node_id.owner_id()) } {
            Ok(handle) => Ok(handle.1),
            Err(BagAddFailure::IsLocked) => {
                fail!(from self, with RegisterNodeResult::MarkedForDestruction,
                    "{msg} since the service is already marked for destruction.");
            }
            Err(BagAddFailure::OutOfSpace) => {
                fail!(from self, with RegisterNodeResult::ExceedsMaxNumberOfNodes,
                    "{msg} since it would exceed the maximum supported nodes of {}.", self.nodes.capacity());
            }
        }
    }

    pub(crate) fn list_node_ids<F: FnMut(&UniqueNodeId) -> CallbackProgression>(
        &self,
        mut callback: F,
    ) {
        let state = unsafe { self.nodes.get_state() };
        state.for_each(|_, node_id| callback(node_id));
    }

    pub(crate) fn deregister_node_id(
        &self,
        handle: B::BagHandle,
    ) -> Result<DeregisterNodeState, BagRemoveError> {
        match unsafe { self.nodes.remove(handle, ReleaseMode::LockIfLastIndex) } {
            Ok(ReleaseState::Locked) => Ok(DeregisterNodeState::NoMoreOwners),
            Ok(ReleaseState::Unlocked) => Ok(DeregisterNodeState::HasOwners),
            Err(BagRemoveError::HandleNotOwnedByInstance) => {
                fail!(from self, with BagRemoveError::HandleNotOwnedByInstance,
                    "Unable to deregister the node since it was not registered.");
            }
        }
    }

    pub(crate) fn request_response(&self) -> &request_response::DynamicConfig<B> {
        // DEAR PATCH: not by the shared tag (see `DearShadow`).
        self.dear_payload::<request_response::DynamicConfig<B>>()
    }

    pub(crate) fn publish_subscribe(&self) -> &publish_subscribe::DynamicConfig<B> {
        // DEAR PATCH: not by the shared tag (see `DearShadow`).
        self.dear_payload::<publish_subscribe::DynamicConfig<B>>()
    }

    pub(crate) fn event(&self) -> &event::DynamicConfig<B> {
        // DEAR PATCH: not by the shared tag (see `DearShadow`).
        self.dear_payload::<event::DynamicConfig<B>>()
    }

    pub(crate) fn blackboard(&self) -> &blackboard::DynamicConfig<B> {
        // DEAR PATCH: not by the shared tag (see `DearShadow`).
        self.dear_payload::<blackboard::DynamicConfig<B>>()
    }
}
