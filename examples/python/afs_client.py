"""What the afs Python clients share: a node on a stack's prefix, and a subscriber of one of its
publish-subscribe services, waiting while the stack (or the link to it) is starting, and refusing
clearly when the stack's message layout is not the client's (docs/messages.md, *Versions*)."""

import ctypes
import os
import re
import sys
import time

import iceoryx2 as iox2


def layout_version(type_name):
    """The layout version an afs type name carries: `afs::Name.vN` is N, `afs::Name` is 1."""
    m = re.search(r"\.v(\d+)$", type_name)
    return int(m.group(1)) if m else 1


def root_path():
    """The iceoryx2 root folder of this user's stacks, by afs's rule (processes/ipc/mod.rs,
    `root_path`): `/tmp/iceoryx2/` for root, `/tmp/iceoryx2-<uid>/` for any other user, the
    user being the machine's (inside a user namespace, root is the user who made it)."""
    uid = os.getuid()
    try:
        with open("/proc/self/uid_map", encoding="ascii") as f:
            for line in f:
                fields = [int(x) for x in line.split()]
                if len(fields) == 3 and fields[0] <= uid < fields[0] + fields[2]:
                    uid = fields[1] + uid - fields[0]
                    break
    except (OSError, ValueError):
        pass
    return "/tmp/iceoryx2/" if uid == 0 else f"/tmp/iceoryx2-{uid}/"


def stack_config(prefix):
    """The iceoryx2 config of stack ``prefix``: its file-name prefix (docs/messages.md) under
    this user's root folder."""
    config = iox2.config.global_config()
    config.global_cfg.prefix = iox2.FileName.new(f"afs_{prefix}_")
    config.global_cfg.root_path = iox2.Path.new(root_path())
    return config


def service_payload(config, service_name):
    """The payload type name and size of the publish-subscribe service `service_name`, or None.

    iceoryx2's Python binding (0.10) gives a service's static config only in its text form,
    which names the payload's type and size."""
    try:
        details = iox2.Service.details(
            iox2.ServiceName.new(service_name),
            config,
            iox2.MessagingPattern.PublishSubscribe,
            iox2.ServiceType.Ipc,
        )
    except Exception:  # pylint: disable=broad-except
        return None
    if details is None:
        return None
    m = re.search(r'payload: TypeDetail \{.*?data: "([^"]*)".*?size: (\d+)', str(details), re.S)
    return (m.group(1), int(m.group(2))) if m else None


def subscribe(prefix, service_name, payload_type, deadline, buffer_size=None, node_name=None):
    """A subscriber of ``service_name`` (payload ``payload_type``) of stack ``prefix``, and the
    node that owns it (keep both alive); None if the service is not there by ``deadline``
    (``time.monotonic()``), or carries another layout version than ``payload_type``, said on
    stderr. ``node_name`` names the node (what `afs run` reports of a client still attached
    when the stack ends)."""
    iox2.set_log_level_from_env_or(iox2.LogLevel.Warn)
    config = stack_config(prefix)
    builder = iox2.NodeBuilder.new().config(config)
    if node_name is not None:
        builder = builder.name(iox2.NodeName.new(node_name))
    node = builder.create(iox2.ServiceType.Ipc)
    ours = payload_type.type_name()
    while True:
        try:
            service = (
                node.service_builder(iox2.ServiceName.new(service_name))
                .publish_subscribe(payload_type)
                .open()
            )
            break
        except Exception as e:  # the stack may still be starting
            theirs = service_payload(config, service_name)
            if theirs is not None and theirs[0] != ours:
                print(
                    f"'{service_name}' of stack '{prefix}' carries {theirs[0]} (layout version "
                    f"{layout_version(theirs[0])}, {theirs[1]} bytes); this client reads {ours} "
                    f"(layout version {layout_version(ours)}, {ctypes.sizeof(payload_type)} "
                    "bytes): update the client's struct from docs/messages.md",
                    file=sys.stderr,
                )
                return None
            if time.monotonic() > deadline:
                print(f"no afs stack with prefix '{prefix}': {e}", file=sys.stderr)
                return None
            time.sleep(0.1)
    builder = service.subscriber_builder()
    if buffer_size is not None:
        builder = builder.buffer_size(buffer_size)
    return node, builder.create()
