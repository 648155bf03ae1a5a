"""The ``bags`` service of a simulator worker (sessgan_interfaces/WorkerBags) as a
:class:`~sessgan_evolver.bag_collection.BagSource`, and the worker's description."""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

from sessgan_evolver.errors import BagCollectionError

SERVICE_TIMEOUT = 30.0
"""Wall seconds a worker may take to answer one request (a chunk is at most 1 MiB)."""


class RemoteBagSource:
    """Requests to ``<namespace>/bags``, answered while ``spin`` runs the node's callbacks."""

    def __init__(self, node: Any, namespace: str, spin: Callable[[float], None],
                 timeout: float = SERVICE_TIMEOUT) -> None:
        from sessgan_interfaces.srv import WorkerBags

        self.request_type = WorkerBags.Request
        self.service = f'{namespace}/bags'
        self.client = node.create_client(WorkerBags, self.service)
        self.spin = spin
        self.timeout = timeout

    def call(self, **fields: Any) -> Any:
        """The response to a request of ``fields``; BagCollectionError if the worker gives no
        answer within ``timeout`` or refuses."""
        return self.call_within(self.timeout, **fields)

    def call_within(self, timeout: float, **fields: Any) -> Any:
        """``call`` with its own ``timeout``; no fields: the worker's description."""
        deadline = time.monotonic() + timeout
        while not self.client.service_is_ready():
            if time.monotonic() > deadline:
                raise BagCollectionError(f'no worker answers at {self.service} (a simulator '
                                         'of an older version serves no bags)')
            self.spin(0.05)
        request = self.request_type()
        for name, value in fields.items():
            setattr(request, name, value)
        future = self.client.call_async(request)
        while not future.done():
            if time.monotonic() > deadline:
                self.client.remove_pending_request(future)
                raise BagCollectionError(f'{self.service} gave no answer within '
                                         f'{timeout:.0f} s')
            self.spin(0.01)
        response = future.result()
        if not response.success:
            raise BagCollectionError(f'{self.service}: {response.message}')
        return response

    def list_files(self, bag: str) -> dict[str, int]:
        response = self.call(bag=bag)
        if len(response.files) != len(response.sizes):
            raise BagCollectionError(f'{self.service}: a listing of {len(response.files)} '
                                     f'names and {len(response.sizes)} sizes')
        return {str(name): int(size) for name, size in zip(response.files, response.sizes)}

    def read(self, bag: str, name: str, offset: int, length: int) -> bytes:
        return bytes(self.call(bag=bag, file=name, offset=offset, length=length).data)

    def remove(self, bag: str) -> None:
        self.call(bag=bag, remove=True)

    def destroy(self) -> None:
        self.client.destroy()
