"""Which Franka arm a description is, and which binding of libfranka speaks to it.

A Franka arm's controller speaks libfranka's protocol in the version of its robot system
(its "robot server" version, told at every connection): the Panda (Franka Emika Robot,
FER) versions 2-5, which only libfranka < 0.10 speaks, the FR3 versions 6-10, which only
libfranka >= 0.10 speaks, one version per libfranka release (Franka's compatibility
matrix; each description's ``franka.toml``, :data:`MODEL_FILE`). Two adapters drive them,
each through the binding its extra installs (:data:`BINDINGS`):

* ``--arm franka:HOST``, :class:`~qpavoid.drive.franka.FrankaArm`: franky-control 2
  (libfranka 0.21, version 10: an FR3 on robot system 5.9.0 or later);
* ``--arm panda:HOST``, :class:`~qpavoid.drive.panda.PandaArm`: panda-python 1
  (libfranka 0.9.2, version 5: a Panda on robot system 4.2.1 or later).

At connect, the version the arm's controller speaks is checked against the description
the run was given (:meth:`FrankaModel.check`): a Panda answering for ``--robot fr3``, or
an FR3 for ``--robot panda``, is refused in one line naming both before anything moves;
an arm of the right model whose version the binding does not speak is refused naming the
adapter that does, if any (:func:`~qpavoid.drive.libfranka_connection.connect_error`).
"""

from __future__ import annotations

from dataclasses import dataclass
from importlib import resources
from pathlib import Path

from qpavoid.arm.fields import refused
from qpavoid.arm.model import Robot
from qpavoid.core.checks import one_line
from qpavoid.core.errors import ArmError, InputError, RobotDescriptionError
from qpavoid.core.file_bounds import NotTOMLError, read_toml
from qpavoid.core.schema import convert
from qpavoid.drive.franka_model_schema import ModelFile

__all__ = [
    "BINDINGS",
    "FRANKY",
    "MODEL_FILE",
    "PANDA_PY",
    "Binding",
    "FrankaModel",
    "bundled_models",
]

#: The file of a description folder that says which Franka arm it is (``model``, a name for
#: messages; ``server_versions``, the versions of libfranka's protocol its controllers
#: speak; ``[sources]``): ``robots/fr3/franka.toml``, ``robots/panda/franka.toml``.
MODEL_FILE = "franka.toml"
#: Most bytes a model file may have (each bundled one has under 2 kB).
MAX_MODEL_BYTES = 64 * 1024


@dataclass(frozen=True)
class Binding:
    """A Python binding of libfranka, as an adapter's extra installs it.

    Attributes
    ----------
    kind
        The adapter's ``--arm`` kind (``franka:HOST``).
    package
        The binding's package on PyPI.
    extra
        qpavoid's extra that installs it.
    server_version
        The version of libfranka's protocol its bundled libfranka speaks (the only one it
        can connect to).
    libfranka
        That libfranka's release.
    """

    kind: str
    package: str
    extra: str
    server_version: int
    libfranka: str

    def install(self) -> str:
        """How to install it, for messages."""
        return f'pip install "qpavoid[{self.extra}]"'


#: franky-control 2.0's wheel bundles libfranka 0.21.2 and panda-python 1.x's PyPI wheels
#: libfranka 0.9.2 (read from the wheels); the versions they speak are what each offers
#: at connect (tests/test_franka.py and tests/test_panda.py check both on the bindings
#: themselves).
FRANKY = Binding("franka", "franky-control", "franka", 10, "0.21")
PANDA_PY = Binding("panda", "panda-python", "panda", 5, "0.9.2")
BINDINGS = (FRANKY, PANDA_PY)


@dataclass(frozen=True)
class FrankaModel:
    """Which Franka arm a description is: its folder's ``franka.toml`` (:data:`MODEL_FILE`).

    Attributes
    ----------
    name
        The arm's model, as Franka names it (``"FR3"``, ``"Panda (FER)"``).
    server_versions
        The versions of libfranka's protocol its controllers speak (one per robot system
        generation).
    robot
        The description's name, as ``--robot`` takes it.
    """

    name: str
    server_versions: tuple[int, ...]
    robot: str

    @classmethod
    def of(cls, robot: Robot) -> FrankaModel:
        """The model of a description, from the ``franka.toml`` beside its control-point file.

        Raises
        ------
        InputError
            The description has no ``franka.toml`` (a Franka arm it does not say which).
        RobotDescriptionError
            The file cannot be read, is not TOML, or its keys are not a model's.
        """
        folder = None if robot.path is None else Path(robot.path).parent
        if folder is None or not (folder / MODEL_FILE).is_file():
            raise InputError(
                f"the description {robot.name!r} does not say which Franka arm it is (no "
                f"{MODEL_FILE} beside its control-point file, as robots/fr3 and robots/panda "
                "have: docs/real-robot.md §1b)",
                name="robot",
                value=robot.name,
            )
        return cls.read(folder / MODEL_FILE, robot.name)

    @classmethod
    def read(cls, path: Path, robot: str) -> FrankaModel:
        """Read the model file at ``path`` of the description ``robot``.

        Raises
        ------
        RobotDescriptionError
            The file cannot be read, is not TOML, or is not of
            :class:`~qpavoid.drive.franka_model_schema.ModelFile`'s shape (an unknown key,
            no ``model`` text, no ``server_versions`` list of whole numbers from 1 to
            65535), in one line naming the field's path.
        """
        try:
            data = read_toml(path, MAX_MODEL_BYTES)
        except NotTOMLError as exc:
            raise RobotDescriptionError(f"{path}: {one_line(exc)}", path=path) from None
        except (OSError, ValueError) as exc:
            raise RobotDescriptionError(
                f"{path}: cannot read the model file: {one_line(exc)}", path=path
            ) from None
        file = convert(data, ModelFile, refused(path))
        return cls(file.model.strip(), tuple(sorted(set(file.server_versions))), robot)

    def speaks(self, version: int) -> bool:
        """Whether this model's controllers speak ``version`` of libfranka's protocol."""
        return version in self.server_versions

    def versions_text(self) -> str:
        """Its versions, for messages (``"2-5"``, ``"6-10"``, ``"3, 5"``)."""
        v = self.server_versions
        if len(v) > 1 and v == tuple(range(v[0], v[-1] + 1)):
            return f"{v[0]}-{v[-1]}"
        return ", ".join(map(str, v))

    def check(self, arm: str, version: int, reported: str | None = None) -> None:
        """Refuse the arm ``arm`` whose controller speaks ``version`` of libfranka's protocol
        (and names its model ``reported``, if it does) unless this model speaks it.

        Raises
        ------
        ArmError
            "model": another arm answered (:meth:`mismatch`).
        """
        error = self.mismatch(arm, version, reported)
        if error is not None:
            raise error

    def mismatch(self, arm: str, version: int, reported: str | None = None) -> ArmError | None:
        """None if this model speaks ``version``; else the error "model" for the arm ``arm``,
        in one line naming both (and the bundled description whose model speaks
        ``version``, if any)."""
        if self.speaks(version):
            return None
        says = f" and names its model {reported!r}" if reported else ""
        return ArmError(
            f"{arm}: the arm is not the {self.name} that --robot {self.robot} describes: its "
            f"controller speaks version {version} of libfranka's protocol ({_whose(version)})"
            f"{says}, where the {self.name}'s speaks {self.versions_text()}",
            arm=arm,
            reason="model",
            value=version,
        )


def bundled_models() -> tuple[FrankaModel, ...]:
    """The models of the bundled descriptions that have a ``franka.toml``."""
    root = Path(str(resources.files("qpavoid.robots")))
    return tuple(
        FrankaModel.read(folder / MODEL_FILE, folder.name)
        for folder in sorted(root.iterdir())
        if (folder / MODEL_FILE).is_file()
    )


def _whose(version: int) -> str:
    """Whose version ``version`` is among the bundled models, for messages."""
    for model in bundled_models():
        if model.speaks(version):
            return f"the {model.name}'s: --robot {model.robot}"
    known = ", ".join(f"{m.name} {m.versions_text()}" for m in bundled_models())
    return f"no bundled description's arm speaks it: {known}"
