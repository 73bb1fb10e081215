"""Python client for the Penumbra lighting service (protocol/SPEC.md)."""
from penumbra_client.client import (Client, Frame, Node, PenumbraError, Primitive,  # noqa: F401
                                    SceneInfo)

__all__ = ["Client", "Frame", "Node", "PenumbraError", "Primitive", "SceneInfo"]
