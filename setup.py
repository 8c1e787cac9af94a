"""Packaging for ohra. All package data lives under ``ohra/`` (``urdf/`` at the top is a link to ``ohra/urdf``)."""

from pathlib import Path

from setuptools import find_packages, setup

HERE = Path(__file__).parent

setup(
    name="ohra",
    version="0.1.0",
    description="One canonical form for every dexterous robot hand, and cross-embodiment grasping on it",
    long_description=(HERE / "README.md").read_text(encoding="utf-8"),
    long_description_content_type="text/markdown",
    python_requires=">=3.10",
    packages=find_packages(include=["ohra", "ohra.*"]),
    package_data={
        "ohra": ["urdf/templates/*.j2", "urdf/*/*.urdf"],
        "ohra.hands": ["specs/*.yaml", "params/*/*.json", "leap/*.yaml", "leap/*.json"],
        "ohra.learn": ["models/*/*"],
    },
    install_requires=[
        "numpy>=1.24",
        "scipy>=1.10",
        "pin>=3.0",
        "coal>=3.0",
        "casadi>=3.6",
        "jinja2>=3.0",
        "xacro>=2.0",
        "trimesh>=4.0",
        "pybullet>=3.2.5",
        "meshcat>=0.3.2",
        "pyyaml>=6.0",
        "tqdm>=4.60",
        "matplotlib>=3.7",
        "rtree>=1.0",
    ],
    extras_require={
        # torch: on the CPU-only build machines install the provided CPU wheel first (see .ci/run).
        "learn": ["torch>=2.1"],
        # a cluster backend for dataset builds and evaluation (the default is a local process pool)
        "ray": ["ray>=2.9"],
        # in-hand rotation: the Gymnasium env (gymnasium) and PPO training (stable-baselines3, needs torch;
        # sb3-contrib for the recurrent policy option, tensorboard for the optional training logs)
        "rl": ["gymnasium>=1.0", "stable-baselines3>=2.3", "sb3-contrib>=2.3", "tensorboard>=2.10"],
        "dev": ["pytest>=7", "pytest-xdist>=3", "hypothesis>=6", "nbclient>=0.8", "nbformat>=5", "ipykernel>=6"],
    },
    entry_points={"console_scripts": ["ohra=ohra.cli:main"]},
)
