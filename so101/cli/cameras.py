"""`so101 cameras`: the cameras this computer has (V4L2 capture devices: path, name, the sizes and
frame rates each offers), as `lerobot-find-cameras opencv` lists them; `--save DIR` keeps one picture
from each, to see which camera is which before `so101 teleop --body real --camera front=...`.

And where a camera stands, against the simulated one of the same name:
- `--default NAME` prints the simulated camera's own file (the start of a fit, a template to edit);
- `--fit NAME --from DATASET` fits the camera's place and field of view to an episode's pictures and
  joint states (so101.camera_pose.fit) and writes its camera file (`-o FILE`);
- `--align NAME` shows the live picture and the simulated camera's picture of the arm where it stands
  now, one over the other, to move the camera until the two arms coincide.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from so101.cameras.listing import find_cameras, listing_lines, picture_file_name
from so101.dataset.units import UNITS, UNITS_HELP
from so101.runtime.argtypes import number, whole_number

# A camera's first pictures are often dark or half-exposed while it adjusts: this many are let go first.
WARM_UP_PICTURES = 10
CAMERA_NAMES = ("front", "wrist")


def add_arguments(parser: argparse.ArgumentParser, name: str) -> None:
    parser.add_argument("--save", type=Path, metavar="DIR", default=None,
                        help="also save one picture from each camera in DIR (made if missing), as videoN.png")
    doing = parser.add_mutually_exclusive_group()
    doing.add_argument("--default", choices=CAMERA_NAMES, metavar="NAME", default=None,
                       help="print the simulated camera NAME's file (front or wrist): where a task's episodes draw it "
                            "from, the start of every fit and a template to edit")
    # The wrist camera moves with the jaws: its pictures show no arm moving, so only the front is fitted and aligned.
    doing.add_argument("--fit", choices=("front",), metavar="NAME", default=None,
                       help="fit camera NAME's place and field of view (front: the wrist camera is not fitted) to the "
                            "pictures of the arm in --from DATASET's episode, and write its camera file (-o FILE)")
    doing.add_argument("--backdrop", choices=CAMERA_NAMES, metavar="NAME", default=None,
                       help="make a backdrop for camera NAME (`--backdrop NAME=IMAGE` on demos, eval, teleop, learn) "
                            "from --from SOURCE: a camera (/dev/video0, 0) or a video, the arm out of view or moving "
                            "(each pixel the median of the frames), or a recorded episode, the arm drawn by the "
                            "simulator from --camera-pose NAME=FILE and left out; writes -o FILE.png")
    doing.add_argument("--align", choices=("front",), metavar="NAME", default=None,
                       help="show camera NAME's live picture (--camera NAME=SOURCE) with the simulated camera's "
                            "picture of the arm (--port, or so101 fake-arm) over it, to move the camera into place")
    parser.add_argument("--from", dest="dataset", type=Path, metavar="DATASET", default=None,
                        help="--fit: the LeRobot dataset whose episode's video and joint states are fitted; "
                             "--backdrop: that, or a camera (/dev/video0, 0) or a video file")
    parser.add_argument("--units", choices=UNITS, default=None, help="--fit: " + UNITS_HELP)
    parser.add_argument("--episode", type=whole_number(0, 10**9), metavar="N", default=None,
                        help="--fit, --backdrop: the dataset's episode (default 0)")
    parser.add_argument("--near", type=Path, metavar="FILE", default=None,
                        help="--fit: start from this camera file (a rough measurement) instead of the simulated camera's")
    parser.add_argument("-o", "--output", type=Path, metavar="FILE", default=None,
                        help="--fit: the camera file written (default: printed only); --backdrop: the picture "
                             "written (.png, .jpg); an existing file is kept unless it succeeds")
    parser.add_argument("--size", metavar="WxH", default=None,
                        help="--default: the pictures' size the file says (default 320x240)")
    parser.add_argument("--max-holes", type=number(lambda value: 0 <= value < 1, "a share from 0 to below 1"),
                        default=None, metavar="SHARE",
                        help="--backdrop: the most of the picture the arm may cover in every frame, filled from "
                             "around it (default 0.05); more is refused")
    add_align_arguments(parser)


def _camera_option(text: str) -> tuple[str, str]:
    from so101.cameras.sources import parse_camera_option

    try:
        return parse_camera_option(text)
    except ValueError as error:
        raise argparse.ArgumentTypeError(str(error)) from None


def add_align_arguments(parser: argparse.ArgumentParser) -> None:
    """--align's: the real camera, the arm, where the simulated camera stands, the fitted file, the browser view."""
    from so101.launch.camera_poses import add_camera_pose_option
    from so101.web.settings import DEFAULT_HOST, DEFAULT_PORT

    parser.add_argument("--camera", dest="align_camera", type=_camera_option, metavar="NAME=SOURCE", default=None,
                        help="--align: the real camera NAME: a device (/dev/video0, or its index 0) or a video file")
    parser.add_argument("--port", metavar="PORT", default=None,
                        help="--align: the arm's serial port (/dev/ttyACM0, ...; `so101 fake-arm` prints an emulated "
                             "one); read only, torque off: the arm is moved by hand")
    parser.add_argument("--calibration", type=Path, metavar="FILE", default=None,
                        help="--align: the arm's calibration JSON (from `so101 calibrate`, or LeRobot's so101_follower one); "
                        "--fit: the recording follower's, for joints in normalized units")
    add_camera_pose_option(parser)
    parser.add_argument("--fitted", type=Path, metavar="FILE", default=None,
                        help="--align: where the real camera stands, fitted (`so101 cameras --fit`): then it says in "
                             "words which way to move it")
    parser.add_argument("--web-port", type=whole_number(1, 65535), default=DEFAULT_PORT, metavar="P",
                        help=f"--align: the browser view's port (default {DEFAULT_PORT}; taken, the next free one)")
    parser.add_argument("--web-host", default=DEFAULT_HOST, metavar="ADDRESS",
                        help=f"--align: the address the browser view serves on (default {DEFAULT_HOST}, this machine "
                             "only; 0.0.0.0 serves every network this machine is on)")


def save_picture(path: str, folder: Path) -> str:
    """One picture of the camera at `path` in `folder`; the line that says where, or why not."""
    import cv2

    from so101.cameras.capture import VideoSource

    source = VideoSource(path, None, None, 30)
    why = source.open()
    if why is not None:
        return f"{path}: no picture saved: {why} (in use by another program?)"
    try:
        read = None
        for _ in range(WARM_UP_PICTURES):
            read = source.read() or read
    finally:
        source.close()
    if read is None:
        return f"{path}: no picture saved: it gave none (in use by another program?)"
    rgb = read[0]
    target = folder / picture_file_name(path)
    if not cv2.imwrite(str(target), cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR)):
        return f"{path}: no picture saved: {target} cannot be written"
    return f"{path}: saved {target} ({rgb.shape[1]}x{rgb.shape[0]})"


def fail(line: str) -> int:
    print(f"so101 cameras: {line}", file=sys.stderr)
    return 2


def print_default(name: str, size_text: str | None) -> int:
    from so101.bodies.camera_file import default_camera_file
    from so101.runtime.argtypes import image_size

    try:
        width, height = image_size(size_text) if size_text else (320, 240)
    except (ValueError, argparse.ArgumentTypeError) as error:
        return fail(f"--size {size_text}: {error}")
    sys.stdout.write(default_camera_file(name, width, height).as_json())
    return 0


def fit(args: argparse.Namespace) -> int:
    from so101.bodies.camera_file import CameraFileError, default_camera_file, read_camera_file
    from so101.camera_pose.fit import CameraFitError, fit_from_dataset

    if args.dataset is None:
        return fail("--fit NAME needs --from DATASET: the episode whose pictures and joint states are fitted")
    try:
        start = read_camera_file(args.near, args.fit) if args.near is not None else default_camera_file(args.fit)
    except CameraFileError as error:
        return fail(f"--near {error}")
    try:
        fitted = fit_from_dataset(args.dataset.expanduser(), start, args.episode or 0, log=say, units=args.units,
                                  calibration=args.calibration and args.calibration.expanduser())
    except (CameraFitError, CameraFileError) as error:
        return fail(str(error))
    from so101.camera_pose.moves import move_in_words

    # Against the simulated camera, the one demonstrations are drawn from unless --camera-pose says otherwise.
    words = move_in_words(fitted, default_camera_file(args.fit))
    say(f"to stand where the simulated {args.fit} camera does: {words}")
    text = fitted.as_json()
    if args.output is None:
        sys.stdout.write(text)
        return 0
    target = args.output.expanduser()
    try:
        partial = target.with_name(target.name + ".partial")
        partial.write_text(text, encoding="utf-8")
        partial.replace(target)
    except OSError as error:
        return fail(f"{target} cannot be written ({error.strerror or error})")
    say(f"wrote {target}")
    return 0


def say(line: str) -> None:
    """A line for the person, on standard error: standard output holds a camera file alone (`> front.json`)."""
    print(line, file=sys.stderr, flush=True)


LISTING = "the cameras' listing (no --default, --fit or --align)"
# Each mode's own options: (the option, its argparse name, the mode, or modes, it goes with).
MAKING = ("--fit NAME", "--backdrop NAME")
OWN_OPTIONS = (("--from", "dataset", MAKING), ("--episode", "episode", MAKING), ("--near", "near", "--fit NAME"),
               ("-o", "output", MAKING), ("--size", "size", "--default NAME"), ("--save", "save", LISTING),
               ("--camera", "align_camera", "--align NAME"), ("--port", "port", "--align NAME"),
               ("--calibration", "calibration", ("--align NAME", *MAKING)), ("--units", "units", MAKING),
               ("--fitted", "fitted", "--align NAME"), ("--max-holes", "max_holes", "--backdrop NAME"),
               ("--camera-pose", "camera_poses", ("--align NAME", "--backdrop NAME")))


def misplaced_option(args: argparse.Namespace, mode: str) -> str | None:
    """One line for the first option given that belongs to another mode than `mode` (none: None)."""
    for option, dest, goes_with in OWN_OPTIONS:
        modes = goes_with if isinstance(goes_with, tuple) else (goes_with,)
        if mode not in modes and getattr(args, dest):
            return f"{option} goes with {' or '.join(modes)}"
    return None


def make_backdrop(args: argparse.Namespace) -> int:
    """--backdrop NAME: the median of a source's frames, the arm left out, written to -o FILE.png."""
    import cv2

    from so101.perception.backdrop_maker import (
        DEFAULT_MAX_HOLES, BackdropMakingError, episode_frames, median_backdrop, source_frames,
    )

    name = args.backdrop
    if args.dataset is None:
        return fail(f"--backdrop {name} needs --from SOURCE: a camera (/dev/video0, or its index 0), a video file, "
                    "or a recorded dataset")
    if args.output is None or args.output.suffix.lower() not in (".png", ".jpg", ".jpeg"):
        return fail(f"--backdrop {name} needs -o FILE.png (or .jpg): the backdrop written")
    source = args.dataset.expanduser()
    try:
        if (source / "meta" / "info.json").is_file():
            if name != "front":
                return fail("--backdrop wrist --from DATASET: the wrist camera moves with the jaws; make its "
                            "backdrop from a video of the wrist camera instead")
            frames, covered, how = episode_frames(source, args.episode or 0, args.camera_poses.get("front"), args.units,
                                                  args.calibration and args.calibration.expanduser())
        else:
            frames, covered, how = source_frames(str(args.dataset)), None, "the median of its frames"
        picture, seen = median_backdrop(frames, covered, DEFAULT_MAX_HOLES if args.max_holes is None else args.max_holes)
    except (BackdropMakingError, ValueError) as error:
        return fail(str(error))
    target = args.output.expanduser()
    partial = target.with_name(f".{target.name}.partial{target.suffix}")
    if not cv2.imwrite(str(partial), cv2.cvtColor(picture, cv2.COLOR_RGB2BGR)):
        return fail(f"{target} cannot be written")
    partial.replace(target)
    filled = "" if seen == 1 else f", the other {1 - seen:.1%} filled from around it"
    say(f"wrote {target} ({picture.shape[1]}x{picture.shape[0]}): {how}, {len(frames)} frames; {seen:.1%} of the "
        f"picture seen{filled}. Use it: --backdrop {name}={target}")
    return 0


def align(args: argparse.Namespace) -> int:
    from so101.bodies.camera_file import CameraFileError, default_camera_file, read_camera_file
    from so101.camera_pose.align import AlignError, AlignRequest, run_align

    name = args.align
    if args.align_camera is None:
        return fail(f"--align {name} needs --camera {name}=SOURCE: the real camera (/dev/video0, its index 0, "
                    "or a video file)")
    camera, source = args.align_camera
    if camera != name:
        return fail(f"--camera {camera}=...: --align {name} lines up the {name} camera: give --camera {name}=SOURCE")
    if args.port is None or args.calibration is None:
        return fail("--align needs the arm: --port PORT (/dev/ttyACM0, ...; `so101 fake-arm` prints an emulated one) "
                    "and --calibration FILE (from `so101 calibrate`, or LeRobot's so101_follower one)")
    other = [pose for pose in args.camera_poses if pose != name]
    if other:
        return fail(f"--camera-pose {other[0]}=...: --align {name} draws the {name} camera only")
    simulated = args.camera_poses.get(name)
    fitted = None
    if args.fitted is not None:
        try:
            fitted = read_camera_file(args.fitted, name)
        except CameraFileError as error:
            return fail(f"--fitted {error}")
    request = AlignRequest(
        name, source, args.port, args.calibration.expanduser(),
        simulated if simulated is not None else default_camera_file(name),
        "where --camera-pose puts it" if simulated is not None else f"the simulator's own (so101 cameras --default {name})",
        fitted, args.web_host, args.web_port)
    try:
        return run_align(request)
    except AlignError as error:
        return fail(str(error))


def run(args: argparse.Namespace) -> int:
    mode = ("--default NAME" if args.default is not None else "--fit NAME" if args.fit is not None
            else "--align NAME" if args.align is not None else "--backdrop NAME" if args.backdrop is not None
            else LISTING)
    misplaced = misplaced_option(args, mode)
    if misplaced is not None:
        return fail(misplaced)
    if args.default is not None:
        return print_default(args.default, args.size)
    if args.fit is not None:
        return fit(args)
    if args.align is not None:
        return align(args)
    if args.backdrop is not None:
        return make_backdrop(args)
    cameras = find_cameras()
    for line in listing_lines(cameras):
        print(line)
    if args.save is not None and cameras:
        folder = args.save.expanduser()
        folder.mkdir(parents=True, exist_ok=True)
        for camera in cameras:
            print(save_picture(camera.path, folder))
    sys.stdout.flush()
    return 0
