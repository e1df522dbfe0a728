"""What the afs Python clients share: a node on a stack's prefix, and a subscriber of one of its
publish-subscribe services, waiting while the stack (or the link to it) is starting."""

import sys
import time

import iceoryx2 as iox2


def subscribe(prefix, service_name, payload_type, deadline, buffer_size=None):
    """A subscriber of ``service_name`` (payload ``payload_type``) of stack ``prefix``, and the
    node that owns it (keep both alive); None if the service is not there by ``deadline``
    (``time.monotonic()``), said on stderr."""
    iox2.set_log_level_from_env_or(iox2.LogLevel.Warn)
    config = iox2.config.global_config()
    # The stack isolates its shared memory with this file-name prefix (docs/messages.md).
    config.global_cfg.prefix = iox2.FileName.new(f"afs_{prefix}_")
    node = iox2.NodeBuilder.new().config(config).create(iox2.ServiceType.Ipc)
    while True:
        try:
            service = (
                node.service_builder(iox2.ServiceName.new(service_name))
                .publish_subscribe(payload_type)
                .open()
            )
            break
        except Exception as e:  # the stack may still be starting
            if time.monotonic() > deadline:
                print(f"no afs stack with prefix '{prefix}': {e}", file=sys.stderr)
                return None
            time.sleep(0.1)
    builder = service.subscriber_builder()
    if buffer_size is not None:
        builder = builder.buffer_size(buffer_size)
    return node, builder.create()
