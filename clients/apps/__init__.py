"""The client library's apps, started by `armfleet controller` and `armfleet watch`
(service/cli.py): the controller's model (`controller`) with its Tk (`tk_controller`) and
terminal (`tui`) faces, the live table (`watch`), and a world leased while a controller runs
(`lease_session`).

Why a folder of their own: they need Tk, Textual or Rich, which the client-only distribution
(packaging/armfleet-client) does not install; it ships `clients/` without this folder.

May import: the client library's public modules, Tk, Textual and Rich; never `service`.
"""
