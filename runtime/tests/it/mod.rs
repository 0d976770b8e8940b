mod bundle;
mod controller;
mod opencv;
mod pilot;
mod schedule;
mod tracker;
