"""Files: machine YAML (:mod:`~pkmcal.io.machine_file`), numeric CSV tables
(:mod:`~pkmcal.io.tables`) and atomic writes (:mod:`~pkmcal.io.atomic`)."""

from pkmcal.io.atomic import atomic_write_bytes, atomic_write_text, check_output_path
from pkmcal.io.machine_file import (
    load_machine,
    machine_from_text,
    machine_to_text,
    read_machine_file,
    register_machine_kind,
    save_machine,
)
from pkmcal.io.tables import Table, format_table, read_table, write_table

__all__ = [
    "Table",
    "atomic_write_bytes",
    "atomic_write_text",
    "check_output_path",
    "format_table",
    "load_machine",
    "machine_from_text",
    "machine_to_text",
    "read_machine_file",
    "read_table",
    "register_machine_kind",
    "save_machine",
    "write_table",
]
